use super::*;

fn record(i: u32) -> InstanceRecord {
    InstanceRecord {
        tlas_from_blas: [i as f32; 12],
        blas: i,
        flags: i % 7,
        element: i * 3,
        _pad: i ^ 0x55,
    }
}

/// The resident bytes of the mapping that starts at `addr` (`/proc/self/smaps`'s `Rss`).
fn resident_bytes(addr: usize) -> usize {
    let smaps = std::fs::read_to_string("/proc/self/smaps").unwrap();
    let mut lines = smaps.lines();
    while let Some(line) = lines.next() {
        let start = line.split('-').next().unwrap();
        if usize::from_str_radix(start, 16).ok() != Some(addr) {
            continue;
        }
        for l in lines.by_ref() {
            if let Some(kb) = l.strip_prefix("Rss:") {
                let kb: usize = kb.trim().trim_end_matches("kB").trim().parse().unwrap();
                return kb * 1024;
            }
        }
    }
    panic!("no mapping at {addr:#x}");
}

/// The same operations on a heap table and a mapped one: the same records after each.
#[test]
fn mapped_and_heap_tables_agree() {
    let dir = tempfile::tempdir().unwrap();
    let mut heap = InstanceTable::new();
    let mut file = InstanceTable::in_file(dir.path()).unwrap();
    assert!(file.is_mapped() && !heap.is_mapped());
    assert!(file.is_empty());
    for t in [&mut heap, &mut file] {
        t.try_reserve_exact(1000).unwrap();
        assert!(t.capacity() >= 1000);
        // Past the reservation: the mapped table grows (doubling) and keeps what it held.
        for i in 0..100_000 {
            t.push(record(i)).unwrap();
        }
    }
    assert_eq!(heap, file);
    assert_eq!(file.len(), 100_000);
    for t in [&mut heap, &mut file] {
        t.truncate(70_001);
        t.extend_from_within(10..60_010).unwrap();
        t.resize(140_000, record(7)).unwrap();
        t[5..].rotate_left(17);
        // Both directions of an overlapping copy.
        t.copy_within_released(40_000..100_000, 1000);
        t.copy_within_released(0..90_000, 45_000);
        t.release_pages();
        for r in &mut *t {
            r.flags += 1;
        }
    }
    assert_eq!(heap, file);
    assert_eq!(file.len(), 140_000);
    for t in [&mut heap, &mut file] {
        t.resize(3, record(0)).unwrap();
        t.push(record(9)).unwrap();
    }
    assert_eq!(heap, file);
    assert_eq!(file.clone().into_vec(), heap.clone().into_vec());
    assert!(!file.clone().is_mapped());
    // The file has no name: the directory stays empty.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

/// Pushes release the pages behind them: the map's resident size stays near
/// [`RELEASE_EVERY_RECORDS`] records while the table grows far past it, and the records read
/// back unchanged.
#[test]
fn pushes_release_pages_behind() {
    let dir = tempfile::tempdir().unwrap();
    let mut t = InstanceTable::in_file(dir.path()).unwrap();
    let n = 16 * RELEASE_EVERY_RECORDS;
    t.try_reserve_exact(n).unwrap();
    let addr = t.map_addr().unwrap();
    for i in 0..n as u32 {
        t.push(record(i)).unwrap();
    }
    assert_eq!(t.map_addr(), Some(addr), "reserved: no growth");
    let window = RELEASE_EVERY_RECORDS * RECORD_BYTES;
    let resident = resident_bytes(addr);
    assert!(
        resident <= 2 * window,
        "{resident} bytes resident after {} written",
        n * RECORD_BYTES
    );
    assert!((0..n as u32).all(|i| t[i as usize] == record(i)));
    assert!(
        resident_bytes(addr) > 2 * window,
        "read back: resident again"
    );
    t.release_pages();
    assert_eq!(resident_bytes(addr), 0);
    t.resize(2 * n, record(1)).unwrap();
    let addr = t.map_addr().unwrap();
    assert!(resident_bytes(addr) <= 2 * window);
    t.copy_within_released(0..n, n / 2);
    assert!(resident_bytes(addr) <= 4 * window);
    assert!((0..n as u32).all(|i| t[n / 2 + i as usize] == record(i)));
}

/// The stream split's rotate of a range to the table's tail: a mapped table's through a
/// scratch file, a piece at a time, the same records as a slice's `rotate_left`.
#[test]
fn rotate_to_tail_through_a_file_is_rotate_left() {
    let dir = tempfile::tempdir().unwrap();
    let n = 3 * RELEASE_EVERY_RECORDS + 5;
    for (base, count) in [
        (0, 7),
        (10, n - 10),
        (3, 2 * RELEASE_EVERY_RECORDS + 1),
        (0, n),
    ] {
        let mut heap: InstanceTable = (0..n as u32).map(record).collect();
        let mut file = InstanceTable::in_file(dir.path()).unwrap();
        for r in heap.iter() {
            file.push(*r).unwrap();
        }
        heap[base..].rotate_left(count);
        crate::tlas_split::rotate_to_tail(&mut file, base, count, Some(dir.path())).unwrap();
        assert!(heap == file, "base {base} count {count}");
    }
}
