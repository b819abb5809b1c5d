use super::*;

fn record(i: u32) -> InstanceRecord {
    InstanceRecord {
        blas: i,
        element: i * 3,
        _pad: i ^ 0x55,
        ..Default::default()
    }
}

/// The mapped records read as written, before and after their pages are dropped.
#[test]
fn mapped_records_read_back_unchanged_after_release() {
    let dir = tempfile::tempdir().unwrap();
    let records: Vec<InstanceRecord> = (0..100_000).map(record).collect();
    let map = InstanceMap::write(&records, dir.path()).unwrap();
    assert_eq!(map.records(), &records[..]);
    map.release_range(1000, 70_000).unwrap();
    map.release_range(99_999, 200_000).unwrap();
    assert_eq!(map.records(), &records[..]);
    map.release_pages().unwrap();
    assert_eq!(map.records(), &records[..]);
    // The file has no name: the directory stays empty.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

#[test]
fn an_empty_table_maps_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let map = InstanceMap::write(&[], dir.path()).unwrap();
    assert!(map.records().is_empty());
    map.release_pages().unwrap();
}
