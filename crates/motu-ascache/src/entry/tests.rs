use super::*;

const KEY: CacheKey = CacheKey([0xab; 32]);

#[test]
fn header_round_trips_and_each_fault_has_its_reason() {
    let blob = vec![5u8; 100];
    let h = encode_header(&KEY, &blob);
    let file = 172;
    let got = decode_header(&h, &KEY, file).unwrap();
    assert_eq!(got.blob_bytes, 100);
    assert_eq!(got.blob_xxh3, xxh3_64(&blob));
    let reason =
        |h: &[u8; 72], key: &CacheKey, len: u64| decode_header(h, key, len).unwrap_err().reason();
    assert_eq!(reason(&h, &CacheKey([1; 32]), file), WarningReason::Foreign);
    assert_eq!(reason(&h, &KEY, file - 1), WarningReason::Truncated);
    assert_eq!(reason(&h, &KEY, file + 1), WarningReason::Corrupt);
    for at in 0..ENTRY_HEADER_BYTES {
        let mut bad = h;
        bad[at] ^= 0x10;
        assert_eq!(
            reason(&bad, &KEY, file),
            WarningReason::Corrupt,
            "byte {at}"
        );
    }
}

#[test]
fn names_parse_back() {
    let path = entry_path(Path::new("/c"), &KEY);
    let hex = KEY.to_hex();
    assert_eq!(path, PathBuf::from(format!("/c/v1/ab/{hex}.as")));
    assert_eq!(entry_key("ab", &format!("{hex}.as")), Some(KEY));
    assert_eq!(entry_key("cd", &format!("{hex}.as")), None);
    assert_eq!(entry_key("ab", &format!("{hex}.tmp")), None);
    let temp = format!("{}x7Yz1q{TEMP_SUFFIX}", temp_prefix(&KEY, 4242));
    assert_eq!(temp_owner(&temp), Some(4242));
    assert_eq!(temp_owner(&format!(".{hex}.12.tmp")), None);
    assert_eq!(temp_owner(".x.12.ab.tmp"), None);
    assert_eq!(temp_owner(&format!("{hex}.as")), None);
}
