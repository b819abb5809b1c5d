//! Test helpers: a camera pose and a set of controls over two cameras and two elements.

use glam::Vec3;
use motu_abi::camera::CameraPose;
use motu_gpu::RenderOptions;

use crate::{Controls, ViewOptions};

pub(crate) fn pose(z: f32) -> CameraPose {
    CameraPose {
        world_eye: Vec3::new(0.0, 0.0, z),
        world_forward: Vec3::NEG_Z,
        world_up: Vec3::Y,
        fov_deg: 45.0,
        mirror_x: false,
    }
}

pub(crate) fn controls() -> Controls {
    Controls::new(&ViewOptions {
        title: String::new(),
        width: 8,
        height: 8,
        start: pose(0.0),
        cameras: vec![("a".into(), pose(1.0)), ("b".into(), pose(2.0))],
        render: RenderOptions::default(),
        lod_instance: true,
        elements: vec!["x".into(), "y".into()],
        elements_on: vec![true, true],
        speed: 1.0,
        frames: None,
        replay: None,
        panel: true,
        vsync: true,
        accumulate: true,
        denoise: false,
        panel_clicks: Vec::new(),
        display: None,
    })
}
