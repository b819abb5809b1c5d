use motu_abi::camera::CameraPose;

use super::box_meets_view;

/// A 48×27 camera at the origin looking down −z with a 40° vertical field of view.
fn camera() -> motu_abi::camera::CameraParams {
    CameraPose {
        world_eye: [0.0, 0.0, 0.0].into(),
        world_forward: [0.0, 0.0, -1.0].into(),
        world_up: [0.0, 1.0, 0.0].into(),
        fov_deg: 40.0,
        mirror_x: false,
    }
    .params(48, 27)
}

#[test]
fn boxes_in_front_meet_the_view_and_boxes_behind_or_aside_do_not() {
    let c = camera();
    // Straight ahead, and a box around the eye.
    assert!(box_meets_view(&c, [-1.0, -1.0, -11.0], [1.0, 1.0, -9.0]));
    assert!(box_meets_view(&c, [-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]));
    // Behind the camera.
    assert!(!box_meets_view(&c, [-1.0, -1.0, 9.0], [1.0, 1.0, 11.0]));
    // Far to the right, left, above and below of a box 10 ahead (the view is ~±6.5 × ±3.6
    // there).
    assert!(!box_meets_view(&c, [20.0, -1.0, -11.0], [22.0, 1.0, -9.0]));
    assert!(!box_meets_view(
        &c,
        [-22.0, -1.0, -11.0],
        [-20.0, 1.0, -9.0]
    ));
    assert!(!box_meets_view(&c, [-1.0, 8.0, -11.0], [1.0, 10.0, -9.0]));
    assert!(!box_meets_view(&c, [-1.0, -10.0, -11.0], [1.0, -8.0, -9.0]));
    // Straddling the right edge.
    assert!(box_meets_view(&c, [6.0, -1.0, -11.0], [8.0, 1.0, -9.0]));
    // Empty bounds (a TLAS with nothing in it) meet nothing.
    assert!(!box_meets_view(&c, [1.0, 1.0, 1.0], [-1.0, -1.0, -1.0]));
}
