//! Camera files (`json/cameras/…`): one `LookAt` camera each, mirrored into pbrt's handedness.

use std::path::Path;

use super::json::Node;
use super::Importer;
use crate::events::CameraEvent;
use crate::math;
use crate::{Error, Location};

impl Importer<'_> {
    pub(super) fn camera(
        &mut self,
        path: &Path,
        referenced_at: Option<&Location>,
    ) -> Result<(), Error> {
        let Some(input) = self.open(path, referenced_at, None)? else {
            return Ok(());
        };
        let doc = input.tree()?;
        let vec3 = |key: &str| -> Result<[f64; 3], Error> {
            let n = doc
                .get(key)
                .ok_or_else(|| input.invalid(doc.at, format!("a camera needs `{key}`")))?;
            let v: Vec<f64> = n.items().iter().filter_map(Node::as_f64).collect();
            if v.len() != 3 || v.iter().any(|x| !x.is_finite()) {
                return Err(input.invalid(n.at, format!("`{key}` must be 3 finite numbers")));
            }
            Ok([v[0], v[1], v[2]])
        };
        let (eye, look, up) = (vec3("eye")?, vec3("look")?, vec3("up")?);
        let fov = doc.get("fov").and_then(Node::as_f64).unwrap_or(90.0);
        let ratio = doc.get("ratio").and_then(Node::as_f64).unwrap_or(1.0);
        if !(fov.is_finite() && fov > 0.0 && fov < 180.0 && ratio.is_finite() && ratio > 0.0) {
            return Err(input.invalid(
                doc.at,
                format!("camera fov {fov} or ratio {ratio} is out of range"),
            ));
        }
        let Some(look_at) = math::look_at(eye, look, up) else {
            return Err(input.invalid(doc.at, "camera eye, look and up are degenerate"));
        };
        let right_handed = doc.get("handedness").and_then(Node::as_str) != Some("left");
        let camera_from_world = if right_handed {
            math::mul(&math::scale([-1.0, 1.0, 1.0]), &look_at)
        } else {
            look_at
        };
        let Some(world_from_camera) = math::inverse(&camera_from_world) else {
            return Err(input.invalid(doc.at, "camera transform is not invertible"));
        };
        // `fov` spans the image's width; pbrt's spans the shorter side.
        let fov_short = if ratio > 1.0 {
            2.0 * ((fov.to_radians() * 0.5).tan() / ratio).atan().to_degrees()
        } else {
            fov
        };
        let resolution = match doc.get("resolution").map(Node::items) {
            Some([w, h]) => {
                let (w, h) = (w.as_f64().unwrap_or(0.0), h.as_f64().unwrap_or(0.0));
                if !(w >= 1.0 && h >= 1.0 && w <= 65536.0 && h <= 65536.0) {
                    return Err(input.invalid(doc.at, "resolution must be two sizes in 1..=65536"));
                }
                [w as u32, h as u32]
            }
            _ => [1024, ((1024.0 / ratio).round() as u32).clamp(1, 65536)],
        };
        self.stats.cameras += 1;
        self.sink.camera(&CameraEvent {
            kind: "perspective".into(),
            camera_from_world: math::to_f32(&camera_from_world),
            world_from_camera: math::to_f32(&world_from_camera),
            fov_deg: Some(fov_short as f32),
            screen_window: None,
            lens_radius: doc
                .get("lensRadius")
                .and_then(Node::as_f64)
                .filter(|x| x.is_finite())
                .unwrap_or(0.0) as f32,
            focal_distance: doc
                .get("centerOfInterest")
                .and_then(Node::as_f64)
                .filter(|x| x.is_finite())
                .map(|x| x as f32),
            resolution,
            path,
            loc: input.loc(doc.at),
        })?;
        Ok(())
    }
}
