use super::*;

#[test]
fn parts_display_as_in_messages() {
    assert_eq!(Part::Chunk(ChunkId(17)).to_string(), "chunk 17");
    let nodes = Part::Section {
        kind: SectionKind(1),
        name: "nodes".into(),
    };
    assert_eq!(nodes.to_string(), "section nodes");
    let err = PackageError::corrupt(Part::Chunk(ChunkId(3)), "checksum mismatch");
    assert_eq!(
        err.to_string(),
        "corrupt package (chunk 3): checksum mismatch"
    );
}
