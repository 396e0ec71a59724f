//! The process's allocator: mimalloc instead of glibc malloc, holding on to the pages it frees.
//!
//! The training step, the deformation networks and the flow network allocate and free many
//! multi-megabyte buffers per call. With glibc, page faults and kernel page clearing were ≈ 16 % of
//! the `bench deform` profile, and mimalloc's reuse of freed pages makes that benchmark ≈ 15 %
//! faster (docs/notes/benchmarks-history.md, deformation, "Third pass"). By default mimalloc still
//! returns freed pages to the OS a second after they are freed, so a training step on a large model
//! faults them back in, zeroed by the kernel: ≈ 9 000 page faults and 8.5 % of the time of a `full`
//! step at 114k Gaussians. [`keep_freed_pages`] turns that purging off, so the process keeps its
//! peak (1.7 GB for a `full` run, which then takes 16 143 page faults in all) and the `full` run
//! trains in 5337 s instead of 5469 (docs/BENCHMARKS.md, "Deblurring: the exposure model with
//! events").
//!
//! `unsafe` here: two calls into mimalloc's C API, whose Rust bindings lack this option.
#![allow(unsafe_code)]

use std::ffi::{c_int, c_long};

#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

extern "C" {
    // From mimalloc.h (v3, built by libmimalloc-sys 0.1.49), whose Rust bindings lack this option.
    fn mi_option_set(option: c_int, value: c_long);
    #[cfg(test)]
    fn mi_option_get(option: c_int) -> c_long;
}

/// `mi_option_purge_delay` in mimalloc.h's `mi_option_e`: milliseconds between freeing memory and
/// returning it to the OS (default 1000 in v3's options.c; −1: never).
const MI_OPTION_PURGE_DELAY: c_int = 15;

/// Never return freed memory to the OS: the next allocation of the same size reuses the pages
/// without a page fault or the kernel zeroing them. Call first thing in `main`.
pub fn keep_freed_pages() {
    // SAFETY: mimalloc's option setter takes any option id of its enum and any value; options are
    // plain integers read atomically by the allocator.
    unsafe { mi_option_set(MI_OPTION_PURGE_DELAY, -1) };
}

/// The current purge delay (milliseconds; −1: never).
#[cfg(test)]
fn purge_delay() -> c_long {
    // SAFETY: as above, a read of an option.
    unsafe { mi_option_get(MI_OPTION_PURGE_DELAY) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_option_set_is_mimallocs_purge_delay() {
        // The default of `mi_option_purge_delay` in mimalloc v3 is 1000 ms: a wrong enum value
        // would read another option's default (and setting it would change the wrong knob).
        assert_eq!(purge_delay(), 1000);
        keep_freed_pages();
        assert_eq!(purge_delay(), -1);
    }
}
