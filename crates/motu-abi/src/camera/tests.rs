use super::*;

#[test]
fn extrapolating_a_dolly_lands_one_step_further() {
    let at =
        |z: f32| CameraParams::new(Vec3::new(0.0, 1.0, z), Vec3::Z, Vec3::Y, 40.0, false, 8, 6);
    let (a, b) = (at(0.0), at(0.5));
    let next = b.extrapolated_from(&a);
    assert_eq!(next, at(1.0));
    // A held camera stays where it is.
    assert_eq!(b.extrapolated_from(&b), b);
}

#[test]
fn centre_pixel_looks_forward_and_axes_follow_pbrt() {
    let c = CameraParams::new(Vec3::ZERO, Vec3::NEG_Z, Vec3::Y, 90.0, false, 101, 101);
    let d = c.primary_dir(50, 50, 0.5, 0.5);
    assert!((d - Vec3::NEG_Z).length() < 1e-6, "{d}");
    // pbrt without Scale -1: image x grows along cross(up, forward) = -X.
    let right = c.primary_dir(100, 50, 0.5, 0.5);
    assert!(right.x < -0.5, "{right}");
    let mirrored = CameraParams::new(Vec3::ZERO, Vec3::NEG_Z, Vec3::Y, 90.0, true, 101, 101);
    assert!(mirrored.primary_dir(100, 50, 0.5, 0.5).x > 0.5);
    // Row 0 is the top.
    assert!(c.primary_dir(50, 0, 0.5, 0.5).y > 0.5);
}

#[test]
fn fov_spans_the_shorter_axis() {
    let c = CameraParams::new(Vec3::ZERO, Vec3::Z, Vec3::Y, 90.0, false, 200, 100);
    // Top edge centre at 45 degrees from forward (fov on the shorter, vertical axis).
    let top = Vec3::from_array(c.world_dir00) + Vec3::from_array(c.world_du) * 100.0;
    let angle = top.normalize().angle_between(Vec3::Z).to_degrees();
    assert!((angle - 45.0).abs() < 1e-3, "{angle}");
    assert!((c.pixels_per_unit_at_1 - 50.0).abs() < 1e-3);
}

#[test]
fn camera_path_sweeps_and_dollies_deterministically() {
    let base = CameraPose {
        world_eye: Vec3::new(0.0, 1.0, 10.0),
        world_forward: Vec3::NEG_Z,
        world_up: Vec3::Y,
        fov_deg: 45.0,
        mirror_x: false,
    };
    let path = CameraPath::sweep_and_dolly(10.0, 0.3);
    assert_eq!(camera_path(&base, &path, 0, 1), base);
    let first = camera_path(&base, &path, 0, 30);
    let mid = camera_path(&base, &path, 15, 30);
    let last = camera_path(&base, &path, 29, 30);
    let yaw = |p: &CameraPose| p.world_forward.x.atan2(-p.world_forward.z).to_degrees();
    // Yaw about +Y turns -Z towards -X for positive angles.
    assert!((yaw(&first) - 20.0).abs() < 1e-3, "{}", yaw(&first));
    assert!((yaw(&last) + 20.0).abs() < 1e-3, "{}", yaw(&last));
    assert!(yaw(&mid).abs() < 1.5);
    // The eye moves 3 units by the last frame, along the viewing direction.
    assert!((last.world_eye - base.world_eye).length() - 3.0 < 1e-4);
    assert_eq!(first.world_eye, base.world_eye);
    assert!(
        (last.world_eye - base.world_eye)
            .normalize()
            .dot(last.world_forward)
            > 0.999
    );
    // Same inputs, same frame.
    assert_eq!(
        camera_path(&base, &path, 7, 30),
        camera_path(&base, &path, 7, 30)
    );
    assert_eq!(first.params(8, 8), first.params(8, 8));
}

fn pose(x: f32) -> CameraPose {
    CameraPose {
        world_eye: Vec3::new(x, 1.0 / 3.0, -0.1),
        world_forward: Vec3::new(0.1, -0.2, -1.0),
        world_up: Vec3::Y,
        fov_deg: 37.5,
        mirror_x: x > 1.0,
    }
}

#[test]
fn recorded_path_round_trips_exactly_and_samples() {
    let p = RecordedPath {
        poses: vec![pose(0.0), pose(0.7), pose(2.0)],
        width: Some(64),
        height: None,
    };
    let back = RecordedPath::from_json(&p.to_json()).expect("parses");
    assert_eq!(back, p);
    // Same count: the poses themselves; otherwise interpolated.
    assert_eq!(p.sample(1, 3), pose(0.7));
    let mid = p.sample(1, 5);
    assert!((mid.world_eye.x - 0.35).abs() < 1e-6, "{}", mid.world_eye);
    assert_eq!(p.sample(4, 5).world_eye, pose(2.0).world_eye);
}

#[test]
fn bad_camera_paths_are_rejected_with_reasons() {
    let err = |t: &str| RecordedPath::from_json(t).unwrap_err().to_string();
    assert!(err("{").contains("line 1"), "{}", err("{"));
    assert!(err(r#"{"format":"x","version":1,"frames":[]}"#).contains("format"));
    assert!(err(r#"{"format":"motu-camera-path","version":2,"frames":[]}"#).contains("version 2"));
    assert!(err(r#"{"format":"motu-camera-path","version":1,"frames":[]}"#).contains("no frames"));
    let f = r#"{"format":"motu-camera-path","version":1,"frames":[{"eye":[0,0,0],"forward":[0,1,0],"up":[0,2,0],"fov_deg":40}]}"#;
    assert!(
        err(f).contains("frame 0") && err(f).contains("parallel"),
        "{}",
        err(f)
    );
    let f = r#"{"format":"motu-camera-path","version":1,"frames":[{"eye":[0,0,0],"forward":[0,0,1],"up":[0,1,0],"fov_deg":190}]}"#;
    assert!(err(f).contains("fov_deg"), "{}", err(f));
}
