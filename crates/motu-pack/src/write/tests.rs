use super::*;
use motu_abi::{InstanceRecord, TlasRecord};
use motu_package::WriterOptions;

/// The instance table written a piece at a time is the same package, byte for byte, and the
/// pieces named to the hook cover the table in order.
#[test]
fn instances_written_in_pieces_make_the_same_package() {
    let n = INSTANCE_PIECE_RECORDS * 2 + 5;
    let instances: Vec<InstanceRecord> = (0..n as u32)
        .map(|i| InstanceRecord {
            blas: i % 3,
            element: i,
            flags: i >> 4,
            ..Default::default()
        })
        .collect();
    let tlases = [TlasRecord {
        instance_count: n as u32,
        ..Default::default()
    }];
    let view = HierarchyView {
        tlases: &tlases,
        instances: &instances,
        ..Default::default()
    };
    let meta = PackageMeta {
        schema: crate::SCHEMA.into(),
        ..Default::default()
    };
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, pieces: Option<&mut Vec<(usize, usize)>>| {
        let path = dir.path().join(name);
        let mut w = PackageWriter::create(&path, WriterOptions::default()).unwrap();
        match pieces {
            None => write_hierarchy_after_texels(&mut w, &view, &meta).unwrap(),
            Some(p) => {
                write_hierarchy_after_texels_then(&mut w, &view, &meta, &mut |a, b| p.push((a, b)))
                    .unwrap()
            }
        }
        w.finish().unwrap();
        std::fs::read(path).unwrap()
    };
    let mut pieces = Vec::new();
    let whole = write("a.motu", None);
    let in_pieces = write("b.motu", Some(&mut pieces));
    assert!(whole == in_pieces, "the packages differ");
    assert_eq!(pieces.len(), 3);
    assert_eq!(pieces.first().map(|p| p.0), Some(0));
    assert_eq!(pieces.last().map(|p| p.1), Some(n));
    assert!(pieces.windows(2).all(|w| w[0].1 == w[1].0));
}
