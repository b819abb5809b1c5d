use super::*;

#[test]
fn check_zero_reports_first_nonzero_byte() {
    let mut bytes = vec![0u8; 32];
    assert_eq!(check_zero(&bytes, 4, 20).unwrap(), 16);
    bytes[10] = 7;
    let err = check_zero(&bytes, 4, 20).unwrap_err();
    assert!(err.to_string().contains("byte 10 is 0x07"), "{err}");
}
