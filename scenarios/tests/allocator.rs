//! `memory::heap_mb`, `memory::keep_large_blocks_out_of_the_heap` and `memory::release_free_pages`,
//! in a process of their own and in one test (each reads or acts on the whole process): what is
//! held is counted, a large block freed no longer pulls the blocks after it into the heap, and
//! the holes freed blocks leave are given back, by one call and by
//! `memory::release_free_pages_every`'s thread.

#[cfg(all(target_os = "linux", target_env = "gnu"))]
#[test]
fn a_freed_large_block_leaves_the_next_ones_their_own_mappings() {
    use sgm_scenarios::memory::{keep_large_blocks_out_of_the_heap, MMAP_THRESHOLD_BYTES};

    /// Bytes glibc holds in blocks mapped on their own.
    fn mapped() -> usize {
        // SAFETY: mallinfo2 only reads the allocator's counters.
        unsafe { libc::mallinfo2() }.hblkhd
    }

    // heap_mb counts a block while it is held (read here, where no other test allocates).
    let heap = || sgm_scenarios::memory::heap_mb().expect("mallinfo2 with glibc");
    let before = heap();
    let block = std::hint::black_box(vec![1u8; 64 << 20]);
    let held = heap();
    assert!(held - before >= 63.0, "{before} MiB, then {held} MiB with 64 MiB held");
    drop(block);
    assert!(heap() < held - 63.0, "freeing 64 MiB left {} MiB held", heap());

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

    // 512 heap blocks of 64 KiB; every other one freed leaves 16 MiB of holes between blocks
    // still held, which glibc keeps resident until it is asked to give them back.
    let resident = || sgm_scenarios::memory::resident_mb().0.expect("/proc/self/status");
    let mut blocks: Vec<Option<Vec<u8>>> = (0..512).map(|i| Some(vec![i as u8; 64 * 1024])).collect();
    for block in blocks.iter_mut().step_by(2) {
        drop(block.take());
    }
    let freed = resident();
    assert!(sgm_scenarios::memory::release_free_pages(), "nothing was given back");
    let released = resident();
    assert!(freed - released >= 12.0, "16 MiB of holes: {freed:.1} MiB resident, then {released:.1} MiB");

    // The same holes made again, with the periodic release (what `sgm ros` runs) doing the call.
    for (i, block) in blocks.iter_mut().enumerate().step_by(2) {
        *block = Some(vec![i as u8; 64 * 1024]);
    }
    {
        let _release =
            sgm_scenarios::memory::release_free_pages_every(std::time::Duration::from_millis(20)).expect("a thread");
        for block in blocks.iter_mut().step_by(2) {
            drop(block.take());
        }
        let freed = resident();
        // Polled, not timed: the thread gives the pages back within its first few periods.
        let released = (0..500)
            .map(|_| {
                std::thread::sleep(std::time::Duration::from_millis(20));
                resident()
            })
            .find(|&now| freed - now >= 12.0);
        assert!(
            released.is_some(),
            "the periodic release gave nothing back in 10 s: {freed:.1} MiB resident, then {:.1} MiB",
            resident()
        );
    }
    drop(std::hint::black_box(blocks));
}
