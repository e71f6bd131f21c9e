//! SIGTERM and SIGINT as a request to drain, not an instant death: the
//! signals are blocked in every thread (the mask is inherited, so it is set
//! before any thread starts) and one thread takes them with `sigwait`, so
//! what runs on a signal is ordinary code, not a signal handler.

/// The stop signals, blocked and waiting to be taken.
pub struct StopSignals {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    set: libc::sigset_t,
}

#[cfg(all(target_os = "linux", target_env = "gnu"))]
impl StopSignals {
    /// Blocks SIGTERM and SIGINT in the calling thread and in every thread
    /// it starts from now on. Call it before any thread is started.
    pub fn block() -> Option<StopSignals> {
        // SAFETY: `set` is a plain sigset_t, initialised by sigemptyset
        // before any other use; the calls take pointers to it that live
        // across each call only.
        unsafe {
            let mut set: libc::sigset_t = std::mem::zeroed();
            libc::sigemptyset(&mut set);
            libc::sigaddset(&mut set, libc::SIGTERM);
            libc::sigaddset(&mut set, libc::SIGINT);
            let blocked = libc::pthread_sigmask(libc::SIG_BLOCK, &set, std::ptr::null_mut());
            (blocked == 0).then_some(StopSignals { set })
        }
    }

    /// Waits for SIGTERM or SIGINT; its name.
    pub fn wait(&self) -> &'static str {
        let mut signal = 0;
        // SAFETY: `self.set` is an initialised sigset_t and `signal` an int
        // that outlives the call.
        let taken = unsafe { libc::sigwait(&self.set, &mut signal) };
        match (taken, signal) {
            (0, libc::SIGINT) => "SIGINT",
            _ => "SIGTERM",
        }
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
impl StopSignals {
    /// Elsewhere the signals keep their default action.
    pub fn block() -> Option<StopSignals> {
        None
    }

    pub fn wait(&self) -> &'static str {
        unreachable!("no StopSignals exist on this platform")
    }
}
