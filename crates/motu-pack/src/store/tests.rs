use super::*;
use motu_package::WriterOptions;

fn mesh(triangles: u32) -> MeshData {
    MeshData {
        positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        indices: (0..triangles).flat_map(|_| [0, 1, 2]).collect(),
        ..Default::default()
    }
}

/// Meshes over the spill bound are read back from the spill file, never written to the
/// package, and the spill file is gone once the writer is taken.
#[test]
fn meshes_over_the_bound_spill_and_vanish() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("p.motu");
    let opts = WriterOptions::default();
    let spill = PackageWriter::create(dir.path().join("s.motu"), opts.clone()).unwrap();
    let mut g =
        PackageGeometry::new(PackageWriter::create(&out, opts).unwrap()).with_spill(spill, 10);
    let small = g.store(MeshId(0), 0, &mesh(10)).unwrap();
    let big = g.store(MeshId(1), 0, &mesh(11)).unwrap();
    assert!(!PackageGeometry::is_spilled(small));
    assert!(PackageGeometry::is_spilled(big));
    assert_eq!(g.load(MeshId(0), small).unwrap(), mesh(10));
    assert_eq!(g.load(MeshId(1), big).unwrap(), mesh(11));
    let writer = g.take_writer().unwrap();
    let s = writer.finish().unwrap();
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, vec!["p.motu".to_string()], "no spill file left");
    // Only the small mesh's blob is in the package.
    let pkg = motu_package::Package::open(&s.path).unwrap();
    let raw: u64 = pkg.chunks().iter().map(|c| c.raw_len).sum();
    assert_eq!(raw, MeshBlobLayout::of(&mesh(10)).len);
}

/// A raised bound applies from the mesh that brings the stored count to its threshold on;
/// meshes spilled before stay spilled.
#[test]
fn the_spill_bound_rises_once_enough_triangles_were_stored() {
    let dir = tempfile::tempdir().unwrap();
    let opts = WriterOptions::default();
    let spill = PackageWriter::create(dir.path().join("s.motu"), opts.clone()).unwrap();
    let mut g =
        PackageGeometry::new(PackageWriter::create(dir.path().join("p.motu"), opts).unwrap())
            .with_spill(spill, 10)
            .raise_spill_bound_after(40, 20);
    let spilled: Vec<bool> = [15, 15, 15, 15, 25]
        .iter()
        .enumerate()
        .map(|(i, &t)| {
            let at = g.store(MeshId(i as u32), 0, &mesh(t)).unwrap();
            assert_eq!(g.load(MeshId(i as u32), at).unwrap(), mesh(t));
            PackageGeometry::is_spilled(at)
        })
        .collect();
    // 15, 30 stored: over 10 spills; 45 ≥ 40: the bound is 20 from the third mesh on.
    assert_eq!(spilled, vec![true, true, false, false, true]);
}

/// The streams' open chunks are written in group order when the writer is taken, whatever
/// order the groups were opened in: two imports of one scene put every chunk at the same
/// offset (they did not while a map's order decided).
#[test]
fn open_chunks_are_written_in_group_order() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("p.motu");
    let mut g =
        PackageGeometry::new(PackageWriter::create(&out, WriterOptions::default()).unwrap());
    let groups = [7u32, 3, 12, 0, 9, 1, 15, 4, 11, 6];
    for (i, &group) in groups.iter().enumerate() {
        g.store(MeshId(i as u32), group, &mesh(5)).unwrap();
    }
    let s = g.take_writer().unwrap().finish().unwrap();
    let pkg = motu_package::Package::open(&s.path).unwrap();
    let mut by_offset: Vec<(u64, u32)> = pkg.chunks().iter().map(|c| (c.offset, c.group)).collect();
    by_offset.sort_unstable();
    let in_file: Vec<u32> = by_offset.iter().map(|&(_, group)| group).collect();
    let mut sorted = groups.to_vec();
    sorted.sort_unstable();
    assert_eq!(in_file, sorted);
}
