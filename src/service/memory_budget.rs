//! One memory budget for everything a request makes the service hold:
//! request bodies as they arrive, parsed scenes with their indexes,
//! framebuffers and encoded responses until they are written. Each is
//! charged before (or, for a body, as) it is allocated and gives its charge
//! back when dropped; what cannot be charged is refused with 503.
//!
//! The service's own resident set when it starts (code, threads, pools) is
//! charged from the start, so the charges bound what the process has
//! resident, not only what requests hold. Charges are estimates, so the
//! budget is also held against what the process really has resident: a
//! large charge is only taken if the resident set plus the charge stays
//! within the budget.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

pub struct MemoryBudget {
    limit: u64,
    used: AtomicU64,
}

/// Bytes charged to a [`MemoryBudget`]; given back when dropped.
#[derive(Debug)]
pub struct Charge {
    budget: Arc<MemoryBudget>,
    bytes: u64,
}

impl std::fmt::Debug for MemoryBudget {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "MemoryBudget({}/{})", self.used(), self.limit)
    }
}

impl MemoryBudget {
    /// A budget of `limit` bytes of which `baseline` (the service's own
    /// footprint) are charged for good.
    pub fn new(limit: u64, baseline: u64) -> Arc<Self> {
        Arc::new(MemoryBudget {
            limit,
            used: AtomicU64::new(baseline),
        })
    }

    pub fn limit(&self) -> u64 {
        self.limit
    }

    /// Bytes charged now, the baseline included.
    pub fn used(&self) -> u64 {
        self.used.load(Ordering::Relaxed)
    }

    /// A charge of nothing, to grow.
    pub fn empty(self: &Arc<Self>) -> Charge {
        Charge {
            budget: Arc::clone(self),
            bytes: 0,
        }
    }

    /// Charges `bytes` if both the charges and the measured resident set
    /// leave room for them; `resident` measures the latter (in bytes, `None`
    /// where it cannot be measured).
    pub fn take(
        self: &Arc<Self>,
        bytes: u64,
        resident: impl FnOnce() -> Option<u64>,
    ) -> Option<Charge> {
        let mut charge = self.empty();
        if !charge.grow(bytes) {
            return None;
        }
        let fits = resident().is_none_or(|rss| rss.saturating_add(bytes) <= self.limit);
        fits.then_some(charge)
    }

    fn add(&self, bytes: u64) -> bool {
        self.used
            .fetch_update(Ordering::Relaxed, Ordering::Relaxed, |used| {
                used.checked_add(bytes).filter(|&total| total <= self.limit)
            })
            .is_ok()
    }
}

impl Charge {
    /// Charges `bytes` more; `false` (and nothing charged) if the budget
    /// cannot take them.
    pub fn grow(&mut self, bytes: u64) -> bool {
        let taken = self.budget.add(bytes);
        if taken {
            self.bytes += bytes;
        }
        taken
    }

    /// Gives back all but `bytes` (when the real size is known to be smaller).
    pub fn shrink_to(&mut self, bytes: u64) {
        let give = self.bytes.saturating_sub(bytes);
        self.budget.used.fetch_sub(give, Ordering::Relaxed);
        self.bytes -= give;
    }

    #[cfg(test)]
    pub fn bytes(&self) -> u64 {
        self.bytes
    }
}

impl Drop for Charge {
    fn drop(&mut self) {
        self.budget.used.fetch_sub(self.bytes, Ordering::Relaxed);
    }
}

/// The process's resident set in bytes (`VmRSS`), where Linux tells it.
pub fn resident_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let kib: u64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))?
        .trim()
        .strip_suffix("kB")?
        .trim()
        .parse()
        .ok()?;
    Some(kib * 1024)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn charges_add_up_to_the_limit_and_are_given_back() {
        let budget = MemoryBudget::new(110, 10);
        let mut a = budget.empty();
        assert!(a.grow(60));
        assert!(budget.take(41, || None).is_none());
        let b = budget.take(40, || None).unwrap();
        assert_eq!(budget.used(), 110);
        a.shrink_to(10);
        assert_eq!((a.bytes(), budget.used()), (10, 60));
        drop(b);
        drop(a);
        assert_eq!(budget.used(), 10);
    }

    #[test]
    fn a_charge_that_fits_the_accounts_but_not_the_resident_set_is_refused() {
        let budget = MemoryBudget::new(1000, 0);
        assert!(budget.take(500, || Some(600)).is_none());
        // Nothing stays charged for the refusal.
        assert_eq!(budget.used(), 0);
        assert!(budget.take(500, || Some(500)).is_some());
    }

    #[test]
    fn the_resident_set_is_measured_on_linux() {
        if cfg!(target_os = "linux") {
            let rss = resident_bytes().unwrap();
            assert!(rss > 1024 * 1024 && rss < 1 << 40, "{rss}");
        }
    }
}
