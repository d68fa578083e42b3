//! How freed memory goes back to the system.
//!
//! A training step allocates and frees the same large buffers every time (a grid's table
//! gradient is megabytes; candle's intermediate tensors are too). glibc serves such blocks
//! with `mmap` and returns them on free, so every step pays the kernel again to map fresh
//! zeroed pages, write-fault each one and flush the other cores' TLBs: a quarter of the grid
//! teacher's step went there. [`keep_freed_memory`] makes glibc serve blocks up to 32 MiB
//! from its heap and keep freed memory for the next step.

/// Largest block glibc then serves from its heap (its own ceiling for the setting on 64-bit
/// systems).
pub const HEAP_BLOCK_MAX: usize = 32 << 20;

/// Free memory at the heap's top that glibc keeps instead of returning it.
pub const KEEP_FREED: usize = 1 << 30;

/// Asks glibc to serve blocks up to [`HEAP_BLOCK_MAX`] from its heap and to keep up to
/// [`KEEP_FREED`] of freed memory. Returns whether both settings took; elsewhere than
/// glibc on Linux it does nothing and returns false.
pub fn keep_freed_memory() -> bool {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        // SAFETY: mallopt only changes the allocator's thresholds; it is called before any
        // thread is started, and a rejected value leaves the default in place.
        unsafe {
            libc::mallopt(libc::M_MMAP_THRESHOLD, HEAP_BLOCK_MAX as libc::c_int) == 1
                && libc::mallopt(libc::M_TRIM_THRESHOLD, KEEP_FREED as libc::c_int) == 1
        }
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        false
    }
}
