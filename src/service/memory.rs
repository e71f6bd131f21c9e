//! Giving the memory a burst of requests used back to the system once the
//! service is quiet again.
//!
//! Under glibc's malloc, what the service frees stays with the process: after
//! a minute of overload the arenas held 12 MB of which a few hundred KiB
//! were in use (`malloc_stats`). Concurrent renders free their scenes,
//! indices and tiles in another order than they took them, so much of the
//! render threads' free memory lies in holes under a live chunk, where no
//! `free` gives it back; `malloc_trim` does, and [`spawn_trimmer`] calls it
//! once requests stop for a moment. It cannot give back the free memory at
//! the top of the arenas other than the main one: glibc trims that only in
//! `free`, once it exceeds the trim threshold, which the sliding mmap
//! threshold raises to twice the largest block freed so far. So a render of
//! a small scene must not allocate large blocks: the grid build sizes its
//! occupancy bitmaps to the scene for that reason, among others.
//!
//! On other platforms the trimmer does nothing: their allocators decide for
//! themselves.

use super::State;
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::sync::Arc;
use std::thread::{self, JoinHandle};
use std::time::Duration;

/// How long no request may be answered and no render run before the free
/// memory is given back: long enough not to trim between the requests of a
/// steady load, short enough that the memory is back within about a second
/// of the last request.
const QUIET: Duration = Duration::from_millis(500);

/// Gives the free pages of every malloc arena back to the system.
pub(super) fn trim() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: malloc_trim takes each arena's lock while it works (glibc
    // documents it as MT-Safe), and it only returns pages of free chunks.
    unsafe {
        libc::malloc_trim(0);
    }
}

/// Decides, at each look, whether the service has just become quiet: no
/// request answered since the last look and no render running or waiting,
/// after some activity since the last trim.
#[derive(Debug)]
struct Quiet {
    /// Requests answered at the last look.
    seen: u64,
    /// Requests answered when the memory was last given back.
    trimmed: u64,
}

impl Quiet {
    fn new(answered: u64) -> Self {
        Quiet {
            seen: answered,
            trimmed: answered,
        }
    }

    /// Whether to trim now, given the requests answered so far and whether
    /// any render runs or waits.
    fn look(&mut self, answered: u64, rendering: bool) -> bool {
        let idle = answered == self.seen && !rendering;
        self.seen = answered;
        let trim = idle && answered != self.trimmed;
        if trim {
            self.trimmed = answered;
        }
        trim
    }
}

/// Starts the thread that gives free memory back whenever the service has
/// been quiet for [`QUIET`] after answering requests. It ends when `stop`'s
/// sender is dropped.
pub(super) fn spawn_trimmer(
    state: Arc<State>,
    stop: Receiver<()>,
) -> std::io::Result<JoinHandle<()>> {
    thread::Builder::new()
        .name("voxtrace-trim".into())
        .spawn(move || {
            let answered = || state.metrics.answered();
            let mut quiet = Quiet::new(answered());
            while let Err(RecvTimeoutError::Timeout) = stop.recv_timeout(QUIET) {
                let counts = state.admission.counts();
                if quiet.look(answered(), counts.running + counts.waiting > 0) {
                    trim();
                }
            }
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trims_once_after_activity_then_quiet() {
        let mut quiet = Quiet::new(0);
        // Nothing has happened yet: nothing to give back.
        assert!(!quiet.look(0, false));
        // Requests were answered since the last look: not quiet yet.
        assert!(!quiet.look(5, false));
        // None since: trim, once.
        assert!(quiet.look(5, false));
        assert!(!quiet.look(5, false));
        assert!(!quiet.look(5, false));
    }

    #[test]
    fn never_trims_while_a_render_runs_or_waits() {
        let mut quiet = Quiet::new(0);
        assert!(!quiet.look(3, true));
        // A long render: no request answered, but it still runs.
        assert!(!quiet.look(3, true));
        assert!(!quiet.look(3, true));
        // It finished and was answered.
        assert!(!quiet.look(4, false));
        assert!(quiet.look(4, false));
    }

    #[test]
    fn a_steady_load_is_never_interrupted() {
        let mut quiet = Quiet::new(0);
        for answered in 1..100 {
            assert!(!quiet.look(answered, false), "{answered}");
        }
    }
}
