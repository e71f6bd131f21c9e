//! The heap of a one-shot command: what it frees is kept for what it takes next.
//!
//! glibc's malloc maps each block above its mmap threshold afresh and
//! unmaps it when freed, and gives the top of an arena back to the kernel
//! once it passes the trim threshold. A render reads its text piece by
//! piece and builds its grid through temporary lists, so it frees and takes
//! again hundreds of megabytes, and every page taken again is faulted in
//! and zeroed by the kernel once more. `voxtrace render` and `voxtrace
//! bench` exit soon after, so they keep what they free: blocks up to the
//! largest threshold glibc accepts (32 MiB) come from the arenas, and
//! the arenas are not trimmed: fewer page faults for a larger peak
//! (measured in docs/index.md). The service does the opposite: it gives
//! free memory back once quiet (`service::memory`).
//!
//! On other platforms this does nothing: their allocators decide for themselves.

/// The largest mmap threshold glibc's `mallopt` accepts on 64-bit
/// platforms (`HEAP_MAX_SIZE / 2`): larger blocks are mapped whatever it says.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const LARGEST_MMAP_THRESHOLD: libc::c_int = 32 << 20;

/// Keeps freed memory in the process for its next allocations.
pub fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets two of malloc's parameters under the
    // arenas' locks (glibc documents it as MT-Safe); it touches no memory
    // of the caller's, and a value it refuses leaves the old one.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, LARGEST_MMAP_THRESHOLD);
        libc::mallopt(libc::M_TRIM_THRESHOLD, libc::c_int::MAX);
    }
}
