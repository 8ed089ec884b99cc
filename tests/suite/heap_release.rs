//! Freed heap memory goes back to the system (`runtime::heap`), in a process of its own so
//! no other test's allocations move the resident figure.

#[test]
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn freed_memory_goes_back_to_the_system() {
    use chassisd::runtime::heap::release_free_memory;
    use chassisd::runtime::host::resident_memory_bytes;

    // Many small blocks (below the mmap threshold, so they live in an arena), every 64th
    // kept so the arena cannot simply shrink from its top.
    let blocks: Vec<Vec<u8>> = (0..40_000).map(|i| vec![i as u8; 1000]).collect();
    let kept: Vec<Vec<u8>> = blocks
        .into_iter()
        .enumerate()
        .filter_map(|(i, b)| (i % 64 == 0).then_some(b))
        .collect();
    let before = resident_memory_bytes().expect("VmRSS");
    release_free_memory();
    let after = resident_memory_bytes().expect("VmRSS");
    assert!(
        after + (20 << 20) < before,
        "RSS {before} -> {after} bytes: the freed 39 MB did not go back"
    );
    assert_eq!(kept.len(), 625);
    assert!(kept.iter().enumerate().all(|(i, b)| b[0] == (i * 64) as u8));
}
