use super::*;

#[test]
fn closures_answer_and_short_blobs_have_no_header() {
    let only_ones = |h: &[u8; 32]| h.iter().all(|&b| b == 1);
    assert!(only_ones.compatible(&[1; 32]));
    assert!(!only_ones.compatible(&[2; 32]));
    assert!(AnyDevice.compatible(&[0; 32]));
    assert_eq!(serialized_header(&[7; 40]), Some(&[7; 32]));
    assert_eq!(serialized_header(&[7; 31]), None);
}
