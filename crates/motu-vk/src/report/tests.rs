use super::bytes;

#[test]
fn bytes_are_readable_and_exact() {
    assert_eq!(bytes(512), "512 B");
    assert_eq!(bytes(2 << 30), "2.00 GiB (2147483648)");
    assert_eq!(bytes(1536), "1.50 KiB (1536)");
}
