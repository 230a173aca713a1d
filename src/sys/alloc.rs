//! The process's allocator: the system's, but a request it cannot meet ends the process with
//! one clear line (naming the MPI rank and the size) and exit status 3 (`OUT_OF_MEMORY_STATUS`), instead of Rust's
//! default abort. What the kernel's OOM killer does (SIGKILL) no process can report; this covers
//! what can be reported: a limit (ulimit -v/-d, a cgroup without overcommit) refusing memory.

use std::alloc::{GlobalAlloc, Layout, System};

/// The exit status of a process the system refused memory (docs/farms.md, "Progress, exit status, stopping").
pub const OUT_OF_MEMORY_STATUS: u8 = 3;

pub struct ReportingAllocator;

// SAFETY: every call is forwarded unchanged to the system allocator; only a null result is
// acted on, and then the process ends without returning it.
unsafe impl GlobalAlloc for ReportingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: the caller's contract is passed on.
        let p = unsafe { System.alloc(layout) };
        if p.is_null() {
            out_of_memory(layout.size());
        }
        p
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        // SAFETY: as above.
        let p = unsafe { System.alloc_zeroed(layout) };
        if p.is_null() {
            out_of_memory(layout.size());
        }
        p
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: as above.
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if p.is_null() {
            out_of_memory(new_size);
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: as above.
        unsafe { System.dealloc(ptr, layout) }
    }
}

/// Writes decimal digits of `n` into `buf`; returns the used tail.
fn digits(mut n: u64, buf: &mut [u8; 20]) -> &[u8] {
    let mut i = buf.len();
    loop {
        i -= 1;
        buf[i] = b'0' + (n % 10) as u8;
        n /= 10;
        if n == 0 {
            return &buf[i..];
        }
    }
}

/// Says so on stderr and ends the process. Nothing here may allocate.
fn out_of_memory(size: usize) -> ! {
    let mut line = [0u8; 256];
    let mut len = 0;
    let mut put = |bytes: &[u8]| {
        let n = bytes.len().min(line.len() - len);
        line[len..len + n].copy_from_slice(&bytes[..n]);
        len += n;
    };
    put(b"icrender: error: ");
    // SAFETY: getenv with a NUL-terminated name; the result is read before anything else can
    // change the environment (this thread is about to end the process).
    let rank = unsafe { libc::getenv(c"OMPI_COMM_WORLD_RANK".as_ptr()) };
    if !rank.is_null() {
        put(b"rank ");
        // SAFETY: getenv returned a NUL-terminated string.
        put(unsafe { std::ffi::CStr::from_ptr(rank) }.to_bytes());
        put(b": ");
    }
    put(b"out of memory: the system refused ");
    let mut buf = [0u8; 20];
    put(digits(size as u64, &mut buf));
    put(b" bytes (see --max-memory to check a job's needs before it starts)\n");
    // SAFETY: writing our own buffer to stderr, then ending the process without unwinding or
    // running destructors (which could allocate).
    unsafe {
        libc::write(2, line.as_ptr().cast(), len);
        libc::_exit(OUT_OF_MEMORY_STATUS as i32)
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn digits_without_allocating() {
        let mut buf = [0u8; 20];
        assert_eq!(super::digits(0, &mut buf), b"0");
        assert_eq!(super::digits(1234567, &mut buf), b"1234567");
        assert_eq!(super::digits(u64::MAX, &mut buf), b"18446744073709551615");
    }
}
