//! The one way voxtrace starts worker threads: a rayon pool of a given size,
//! inside which a command does all its parallel work, parsing included.
//! Nothing runs on rayon's global pool, whose size no flag sets, so
//! `--threads N` puts exactly N busy threads on the cores.

use std::fmt;
use std::num::NonZeroUsize;
use std::str::FromStr;

/// How many worker threads: one per core, or a count of at least one.
/// Zero is not a count (it is refused when parsed), so every command reads
/// `--threads` the same way.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Threads {
    #[default]
    AllCores,
    Exactly(NonZeroUsize),
}

impl Threads {
    /// `n` threads; `None` for zero.
    pub fn exactly(n: usize) -> Option<Threads> {
        NonZeroUsize::new(n).map(Threads::Exactly)
    }

    /// What rayon's builder takes, where 0 means one per core.
    fn rayon_count(self) -> usize {
        match self {
            Threads::AllCores => 0,
            Threads::Exactly(n) => n.get(),
        }
    }
}

/// A thread count that is not a whole number of at least one.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ThreadsError {
    Zero,
    NotANumber(String),
}

impl fmt::Display for ThreadsError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ThreadsError::Zero => write!(
                f,
                "the thread count must be at least 1 (leave it out for one per core)"
            ),
            ThreadsError::NotANumber(found) => {
                write!(
                    f,
                    "the thread count must be a whole number, found {found:?}"
                )
            }
        }
    }
}

impl std::error::Error for ThreadsError {}

impl FromStr for Threads {
    type Err = ThreadsError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let n: usize = s
            .parse()
            .map_err(|_| ThreadsError::NotANumber(s.to_owned()))?;
        Threads::exactly(n).ok_or(ThreadsError::Zero)
    }
}

/// The operating system would not start the threads.
#[derive(Debug)]
pub struct PoolError(rayon::ThreadPoolBuildError);

impl fmt::Display for PoolError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "cannot start the worker threads: {}", self.0)
    }
}

impl std::error::Error for PoolError {}

/// A pool of `threads` worker threads, named `voxtrace-worker-N` (as `top`
/// and `/proc` show them).
///
/// ```
/// use voxtrace::threads::{pool, Threads};
/// let two = pool(Threads::exactly(2).unwrap()).unwrap();
/// assert_eq!(two.install(rayon::current_num_threads), 2);
/// ```
pub fn pool(threads: Threads) -> Result<rayon::ThreadPool, PoolError> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads.rayon_count())
        .thread_name(|i| format!("voxtrace-worker-{i}"))
        .build()
        .map_err(PoolError)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_count_is_at_least_one() {
        assert_eq!("3".parse(), Ok(Threads::exactly(3).unwrap()));
        assert_eq!("0".parse::<Threads>(), Err(ThreadsError::Zero));
        assert!(matches!(
            "-1".parse::<Threads>(),
            Err(ThreadsError::NotANumber(_))
        ));
        assert_eq!(Threads::default(), Threads::AllCores);
    }

    #[test]
    fn the_pool_has_the_threads_asked_for() {
        let one = pool(Threads::exactly(1).unwrap()).unwrap();
        assert_eq!(one.current_num_threads(), 1);
        let name = one.install(|| std::thread::current().name().map(str::to_owned));
        assert_eq!(name.as_deref(), Some("voxtrace-worker-0"));
    }
}
