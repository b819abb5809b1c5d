use super::*;

#[test]
fn sizes() {
    for (s, want) in [
        ("64MiB", 64 << 20),
        ("8GiB", 8 << 30),
        ("1048576", 1 << 20),
        ("1.5KiB", 1536),
        ("2gb", 2_000_000_000),
        ("16 M", 16 << 20),
    ] {
        assert_eq!(parse_size(s), Ok(want), "{s}");
    }
    for bad in ["", "MiB", "12XB", "-1", "99999999999TiB"] {
        assert!(parse_size(bad).is_err(), "{bad}");
    }
    assert_eq!(format_size(1536), "1.5 KiB");
    assert_eq!(format_size(12), "12 B");
}
