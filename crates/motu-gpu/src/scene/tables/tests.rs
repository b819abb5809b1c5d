use super::*;

/// The instance layout the shaders and the hardware read: custom index in the low 24 bits
/// of word 12 and the mask in its top byte, which `set_instance_mask` alone changes.
#[test]
fn instance_mask_and_custom_index_share_word_12() {
    let t = [1.0, 0.0, 0.0, 2.0, 0.0, 1.0, 0.0, 3.0, 0.0, 0.0, 1.0, 4.0];
    let word = |i: &[u8; 64]| u32::from_le_bytes(i[48..52].try_into().unwrap());
    let mut inst = encode_instance(&t, false, false, 0xABC0, 0x12_3456);
    assert_eq!(word(&inst), 0xFF12_3456);
    set_instance_mask(&mut inst, 0x04);
    assert_eq!(word(&inst), 0x0412_3456);
    assert_eq!(u64::from_le_bytes(inst[56..64].try_into().unwrap()), 0xABC0);
    assert_eq!(f32::from_le_bytes(inst[12..16].try_into().unwrap()), 2.0);
    // Inactive (no BLAS): mask 0 whatever the index.
    assert_eq!(word(&encode_instance(&t, false, false, 0, 7)), 7);
}
