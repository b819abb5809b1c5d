use super::*;

/// A stand-in for the scene's 52-byte edge (this module does not use the scene's types).
type Edge = [u32; 13];

fn edge(i: u32) -> Edge {
    let mut e = [0u32; 13];
    e[3] = i;
    e[12] = i % 7;
    e
}

#[test]
fn mapped_edges_read_as_the_heap_ones_before_and_after_release() {
    let heap: Vec<Edge> = (0..100_000).map(edge).collect();
    let mut t = EdgeTable::Heap(heap.clone());
    let dir = tempfile::tempdir().unwrap();
    t.move_to_file(dir.path()).unwrap();
    assert!(t.is_mapped());
    assert_eq!(&t[..], &heap[..]);
    t.release_pages().unwrap();
    assert_eq!(&t[..], &heap[..]);
    // The file has no name: the directory stays empty.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    // Moving again is a no-op; an empty table stays on the heap.
    t.move_to_file(dir.path()).unwrap();
    assert_eq!(&t[..], &heap[..]);
    let mut empty = EdgeTable::<Edge>::Heap(Vec::new());
    empty.move_to_file(dir.path()).unwrap();
    assert!(!empty.is_mapped() && empty.is_empty());
}

#[test]
fn a_missing_directory_is_an_error_and_keeps_the_heap_table() {
    let mut t = EdgeTable::Heap(vec![edge(1)]);
    let err = t
        .move_to_file(Path::new("/nonexistent/motu-edges"))
        .unwrap_err();
    assert_eq!(err.kind(), std::io::ErrorKind::NotFound);
    assert!(!t.is_mapped());
    assert_eq!(&t[..], &[edge(1)]);
}
