use super::*;

#[test]
fn kind_indices_match_all_table() {
    for (index, kind) in AllocKind::ALL.iter().enumerate() {
        assert_eq!(kind.index(), index);
    }
    for (index, class) in MemoryClass::ALL.iter().enumerate() {
        assert_eq!(class.index(), index);
    }
}

#[test]
fn byte_size_shows_bytes_and_mib() {
    assert_eq!(ByteSize(3 << 19).to_string(), "1572864 bytes (1.5 MiB)");
}

#[test]
fn binary_scale_picks_the_largest_unit_reached() {
    assert_eq!(binary_scale(0), (0.0, "B"));
    assert_eq!(binary_scale(1023), (1023.0, "B"));
    assert_eq!(binary_scale(1024), (1.0, "KiB"));
    assert_eq!(binary_scale(3 << 29), (1.5, "GiB"));
    assert_eq!(binary_scale(1 << 50), (1024.0, "TiB"));
}
