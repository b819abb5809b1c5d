use super::*;

#[test]
fn kept_buffers_take_a_few_sizes_within_the_cap() {
    assert_eq!(kept_size_bytes(1), TRANSFER_MIN_BYTES);
    assert_eq!(
        kept_size_bytes(TRANSFER_MIN_BYTES + 1),
        2 * TRANSFER_MIN_BYTES
    );
    assert_eq!(kept_size_bytes(100 * MIB), 128 * MIB);
    assert_eq!(kept_size_bytes(TRANSFER_CAP_BYTES), TRANSFER_CAP_BYTES);
}
