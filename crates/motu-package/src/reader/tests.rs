use super::*;

#[test]
fn package_is_shareable_across_threads() {
    fn assert_send_sync<T: Send + Sync>() {}
    assert_send_sync::<Package>();
}

#[test]
fn aligned_bytes_are_64_byte_aligned() {
    for len in [0, 1, 63, 64, 65, 4097] {
        let bytes = AlignedBytes::zeroed(len);
        assert_eq!(bytes.len(), len);
        assert_eq!(bytes.as_ptr() as usize % 64, 0);
    }
}

#[test]
fn bitset_marks_individual_bits() {
    let bits = bitset(130);
    assert_eq!(bits.len(), 3);
    set(&bits, 129);
    assert!(is_set(&bits, 129));
    assert!(!is_set(&bits, 128));
    assert!(!is_set(&bits, 0));
}
