//! Global allocator that aborts on any single allocation over a limit, so a hostile
//! count that reserves a huge (not yet touched) buffer is a finding even though it
//! never shows up in RSS. Fuzz inputs are small: nothing legitimate needs more.

use std::alloc::{GlobalAlloc, Layout, System};

pub struct Guard(pub usize);

// SAFETY: forwards to the system allocator unchanged; only refuses (aborts) early.
unsafe impl GlobalAlloc for Guard {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        self.check(layout.size());
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        self.check(layout.size());
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        self.check(new_size);
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

impl Guard {
    fn check(&self, size: usize) {
        if size > self.0 {
            // No panic here: panicking allocates. libFuzzer reports the abort as a crash.
            let msg = b"alloc_guard: single allocation over the limit\n";
            // SAFETY: writing a static buffer to stderr.
            unsafe { libc_write(2, msg.as_ptr(), msg.len()) };
            std::process::abort();
        }
    }
}

extern "C" {
    #[link_name = "write"]
    fn libc_write(fd: i32, buf: *const u8, count: usize) -> isize;
}
