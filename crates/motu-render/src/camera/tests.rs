use super::*;

fn path(sized: bool) -> RecordedPath {
    let size = if sized {
        r#""width": 80, "height": 45,"#
    } else {
        ""
    };
    let pose =
        |z: f32| format!(r#"{{"eye":[0,0,{z}],"forward":[0,0,-1],"up":[0,1,0],"fov_deg":40}}"#);
    RecordedPath::from_json(&format!(
        r#"{{"format":"motu-camera-path","version":1,{size}"frames":[{},{},{}]}}"#,
        pose(3.0),
        pose(2.0),
        pose(1.0)
    ))
    .unwrap()
}

#[test]
fn recorded_path_cameras_take_the_path_size_and_pose_count_unless_told() {
    let camera = path(false).sample(0, 1).params(64, 36);
    let c = recorded_path_cameras(&path(true), &camera, true, 1);
    assert_eq!(c.len(), 3);
    assert_eq!((c[0].width, c[0].height), (80, 45));
    assert_eq!(
        c[2].world_eye,
        path(true).sample(2, 3).params(80, 45).world_eye
    );
    // A size given on the command line wins; so does a frame count above 1.
    let c = recorded_path_cameras(&path(true), &camera, false, 5);
    assert_eq!((c.len(), c[4].width, c[4].height), (5, 64, 36));
    // No recorded size: the camera's.
    let c = recorded_path_cameras(&path(false), &camera, true, 0);
    assert_eq!((c.len(), c[0].width), (3, 64));
}
