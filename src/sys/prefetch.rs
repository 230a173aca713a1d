//! A hint to the processor to start loading a value's cache line now, for code that knows
//! which memory it will read a little later (a batch of hits, each about to be read) and has
//! other work to do meanwhile. Only a hint: it never faults and changes no result.

/// Starts loading the cache line holding `value` into every cache level.
#[inline(always)]
pub fn prefetch<T>(value: &T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch reads nothing architecturally and cannot fault, whatever the address;
    // SSE (which the instruction needs) is part of every x86_64 processor.
    unsafe {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        _mm_prefetch::<_MM_HINT_T0>(value as *const T as *const i8);
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = value;
}

#[cfg(test)]
mod tests {
    #[test]
    fn prefetching_changes_nothing() {
        let values = vec![1u64, 2, 3];
        for v in &values {
            super::prefetch(v);
        }
        assert_eq!(values, [1, 2, 3]);
    }
}
