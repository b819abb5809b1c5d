use super::*;

#[test]
fn align_up_rounds_and_detects_overflow() {
    assert_eq!(align_up(0, 4096), Some(0));
    assert_eq!(align_up(1, 4096), Some(4096));
    assert_eq!(align_up(4096, 4096), Some(4096));
    assert_eq!(align_up(4097, 8), Some(4104));
    assert_eq!(align_up(u64::MAX, 8), None);
}

#[test]
fn codec_ids_round_trip() {
    for codec in [Codec::Raw, Codec::Zstd] {
        assert_eq!(Codec::from_id(codec.id()), Some(codec));
    }
    assert_eq!(Codec::from_id(2), None);
}

#[test]
fn current_header_checksum_covers_first_56_bytes() {
    let header = Header::current();
    let bytes = bytemuck::bytes_of(&header);
    assert_eq!(&bytes[..8], b"MOTUPKG\0");
    assert_eq!(header.checksum, checksum(&bytes[..56]));
    assert_eq!(
        u64::from_le_bytes(bytes[56..64].try_into().unwrap()),
        header.checksum
    );
}
