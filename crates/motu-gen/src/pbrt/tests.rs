use super::*;

#[test]
fn transform_is_column_major_with_translation_last() {
    let m = Affine::translation([1.5, -2.0, 3.25]).mul(&Affine::uniform_scale(2.0));
    let mut line = Vec::new();
    push_instance(&mut line, &m, "rock", 3);
    let text = String::from_utf8(line).unwrap_or_default();
    assert_eq!(
        text,
        "AttributeBegin Transform [ 2 0 0 0 0 2 0 0 0 0 2 0 1.5 -2 3.25 1 ] ObjectInstance \"rock\" AttributeEnd\n"
    );
}

#[test]
fn small_scales_keep_significant_digits() {
    let m = Affine::uniform_scale(1.234567e-4);
    let mut line = Vec::new();
    push_transform_values(&mut line, &m, 3);
    let text = String::from_utf8(line).unwrap_or_default();
    assert!(text.starts_with("0.000123457 "), "{text}");
}
