//! Settings of mimalloc, the allocator of the `train` and `eval` binaries.
//!
//! A training step allocates and frees the same large tensor buffers over and over. By default
//! mimalloc purges freed memory (gives its pages back to the kernel) after a short delay, so the
//! next step faults the pages in again and the kernel clears each one: on the vision trainer
//! (`configs/t3.toml`, B = 8, T = 16, 64²) page clearing was 15 % of a one-thread profile.
//! [`keep_freed_pages`] turns purging off for the process: its memory stays at the step's peak
//! instead of falling between steps.

/// mimalloc's `mi_option_purge_delay` (its index in `mi_option_t`, mimalloc 3.x): milliseconds
/// before freed memory is purged; -1 never purges. libmimalloc-sys 0.1 names no constant for it.
pub const PURGE_DELAY: i32 = 15;

/// Never purge freed memory in this process (see the module docs), unless the environment sets
/// `MIMALLOC_PURGE_DELAY` (mimalloc's own variable, which then stays in force). Call it first
/// thing in `main`, before any other thread runs: mimalloc's option setter is not thread safe.
pub fn keep_freed_pages() {
    if std::env::var_os("MIMALLOC_PURGE_DELAY").is_none() {
        // SAFETY: sets a plain integer option; the caller runs it before other threads exist.
        unsafe { libmimalloc_sys::mi_option_set(PURGE_DELAY, -1) }
    }
}

/// The purge delay now in force, in milliseconds (-1: never).
pub fn purge_delay_ms() -> std::ffi::c_long {
    // SAFETY: reads a plain integer option.
    unsafe { libmimalloc_sys::mi_option_get(PURGE_DELAY) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn purge_delay_is_mimallocs_default_then_never() {
        // mimalloc 3's default delay is 1 000 ms; an environment that sets it keeps its value.
        let env = std::env::var("MIMALLOC_PURGE_DELAY").ok();
        let expected = env.as_deref().map_or(-1, |v| v.parse().expect("a number"));
        if env.is_none() {
            assert_eq!(purge_delay_ms(), 1000);
        }
        keep_freed_pages();
        assert_eq!(purge_delay_ms(), expected);
    }
}
