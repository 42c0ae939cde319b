//! `memory::keep_large_blocks_out_of_the_heap`, in a process of its own (the setting is
//! process-wide): a large block freed no longer pulls the blocks after it into the heap.

#[cfg(all(target_os = "linux", target_env = "gnu"))]
#[test]
fn a_freed_large_block_leaves_the_next_ones_their_own_mappings() {
    use sgm_scenarios::memory::{keep_large_blocks_out_of_the_heap, MMAP_THRESHOLD_BYTES};

    /// Bytes glibc holds in blocks mapped on their own.
    fn mapped() -> usize {
        // SAFETY: mallinfo2 only reads the allocator's counters.
        unsafe { libc::mallinfo2() }.hblkhd
    }

    assert!(std::env::var_os("MALLOC_MMAP_THRESHOLD_").is_none(), "run without MALLOC_MMAP_THRESHOLD_");
    assert!(keep_large_blocks_out_of_the_heap());
    // glibc's own rule would now raise the threshold to 8 MiB, and the scan-sized block after it
    // would come from the heap.
    drop(std::hint::black_box(vec![1u8; 8 << 20]));
    let before = mapped();
    let scan = std::hint::black_box(vec![1u8; 216_000]);
    let with_scan = mapped();
    assert!(
        with_scan >= before + 216_000,
        "a {} KB block is not mapped on its own (threshold {MMAP_THRESHOLD_BYTES} B): {before} B mapped, then {with_scan} B",
        scan.len() / 1000
    );
    drop(scan);
    assert!(mapped() < with_scan, "freeing the block did not unmap it");
}
