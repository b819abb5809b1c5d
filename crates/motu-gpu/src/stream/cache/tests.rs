use super::*;

#[test]
fn a_proxy_box_table_round_trips_and_refuses_another_layout() {
    let index = [[0u32, 1], [0, 0], [2, 2]];
    let boxes: Vec<Box6> = (0..8)
        .map(|i| [i as f32, 1.0, 2.0, 3.0, 4.0, 5.0 + i as f32])
        .collect();
    let blob = encode_proxy_boxes(&index, &boxes);
    assert_eq!(
        decode_proxy_boxes(&blob, &index, boxes.len()),
        Some(boxes.clone())
    );
    // Another layout, another count, a cut blob, another header: not this table.
    assert_eq!(
        decode_proxy_boxes(&blob, &[[0, 1], [0, 0], [2, 4]], boxes.len()),
        None
    );
    assert_eq!(decode_proxy_boxes(&blob, &index, boxes.len() - 1), None);
    assert_eq!(
        decode_proxy_boxes(&blob[..blob.len() - 1], &index, boxes.len()),
        None
    );
    let mut other = blob.to_vec();
    other[0] ^= 1;
    assert_eq!(decode_proxy_boxes(&other, &index, boxes.len()), None);
}
