use super::*;

fn cam() -> FlyCamera {
    FlyCamera::new(
        CameraPose {
            world_eye: Vec3::ZERO,
            world_forward: Vec3::NEG_Z,
            world_up: Vec3::Y,
            fov_deg: 45.0,
            mirror_x: false,
        },
        2.0,
    )
}

#[test]
fn moves_along_its_axes_at_its_speed() {
    let mut c = cam();
    c.step(
        Motion {
            forward: 1.0,
            ..Default::default()
        },
        0.5,
    );
    assert!((c.pose.world_eye - Vec3::new(0.0, 0.0, -1.0)).length() < 1e-6);
    c.step(
        Motion {
            up: 1.0,
            ..Default::default()
        },
        1.0,
    );
    assert!((c.pose.world_eye.y - 2.0).abs() < 1e-6);
}

#[test]
fn look_pitches_up_for_mouse_up_and_clamps() {
    let mut c = cam();
    c.look(0.0, -100.0, 0.01); // mouse up: look up by 1 rad
    let f = c.pose.world_forward.normalize();
    assert!((f.y - 1f32.sin()).abs() < 1e-4, "{f}");
    c.look(0.0, -10_000.0, 0.01);
    assert!(c.pose.world_forward.normalize().y < 89.1f32.to_radians().sin());
    // Mouse right turns towards image right.
    let mut c = cam();
    let params = c.pose.params(101, 101);
    let right_px = params.primary_dir(100, 50, 0.5, 0.5);
    c.look(50.0, 0.0, 0.01);
    assert!(c.pose.world_forward.normalize().dot(right_px) > Vec3::NEG_Z.dot(right_px));
}
