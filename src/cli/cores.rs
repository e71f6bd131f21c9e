//! The warning for `--threads` above the machine's cores. The count is kept
//! as given, not clamped: `--threads N` is the exact size of the pool (what
//! benchmarks and the thread-count tests rely on), and a container's CPU
//! quota can make the core count the system reports wrong either way. The
//! warning says what the extra threads cost.

use crate::threads::Threads;

/// The warning for `threads` on a machine of `cores` cores, if it is over.
pub fn oversubscribed(threads: Option<Threads>, cores: usize) -> Option<String> {
    let Some(Threads::Exactly(n)) = threads else {
        return None;
    };
    (n.get() > cores).then(|| {
        format!(
            "warning: --threads {n} is more than the {cores} cores here; the extra threads take turns on them and only add overhead (leave --threads out for one per core)"
        )
    })
}

/// Prints [`oversubscribed`]'s warning on stderr, for this machine.
pub fn warn_if_oversubscribed(threads: Option<Threads>) {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    if let Some(warning) = oversubscribed(threads, cores) {
        eprintln!("voxtrace: {warning}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_counts_over_the_cores_warn() {
        let n = |n| Threads::exactly(n);
        assert_eq!(oversubscribed(None, 2), None);
        assert_eq!(oversubscribed(n(2), 2), None);
        let warning = oversubscribed(n(1000), 2).unwrap();
        assert!(
            warning.contains("--threads 1000 is more than the 2 cores"),
            "{warning}"
        );
    }
}
