//! The camera to render and recorded camera paths.

use crate::RenderError;
use glam::Vec3;
use motu_abi::camera::{CameraParams, CameraPath, CameraPose, RecordedPath};
use motu_abi::HierarchyView;
use motu_pack::ScenePackage;

/// The camera to render: by name, else the scene's active camera, else a view of the bounds.
pub fn camera_params(
    pkg: &ScenePackage,
    view: &HierarchyView<'_>,
    name: Option<&str>,
    width: Option<u32>,
    height: Option<u32>,
) -> Result<CameraParams, RenderError> {
    let (pose, w, h) = camera_pose(pkg, view, name, width, height)?;
    Ok(pose.params(w, h))
}

/// The camera as a pose (for camera paths) and the image size.
pub fn camera_pose(
    pkg: &ScenePackage,
    view: &HierarchyView<'_>,
    name: Option<&str>,
    width: Option<u32>,
    height: Option<u32>,
) -> Result<(CameraPose, u32, u32), RenderError> {
    let meta = pkg.meta();
    let cam = match name {
        Some(n) => Some(meta.cameras.iter().find(|c| c.name == n).ok_or_else(|| {
            RenderError::NoCamera {
                name: n.to_string(),
                known: meta.cameras.iter().map(|c| c.name.clone()).collect(),
            }
        })?),
        None => meta.cameras.first(),
    };
    let (eye, fwd, up, fov, mirror, cw, ch) = match cam {
        Some(c) => (
            Vec3::from_array(c.world_eye),
            Vec3::from_array(c.world_forward),
            Vec3::from_array(c.world_up),
            c.fov_deg,
            c.mirror_x,
            c.width,
            c.height,
        ),
        None => {
            // No camera in the scene: look at the root's bounds from the front.
            let r = &view.tlases[view.root_tlas as usize];
            let (lo, hi) = (
                Vec3::from_array(r.bounds_min),
                Vec3::from_array(r.bounds_max),
            );
            let c = (lo + hi) * 0.5;
            let radius = ((hi - lo).length() * 0.5).max(1e-3);
            let eye = c + Vec3::new(0.3, 0.4, 1.0).normalize() * radius * 2.2;
            (eye, (c - eye).normalize(), Vec3::Y, 50.0, false, 640, 480)
        }
    };
    let aspect = cw.max(1) as f64 / ch.max(1) as f64;
    let (w, h) = match (width, height) {
        (Some(w), Some(h)) => (w, h),
        (Some(w), None) => (w, ((w as f64 / aspect).round() as u32).max(1)),
        (None, Some(h)) => (((h as f64 * aspect).round() as u32).max(1), h),
        (None, None) => (cw, ch),
    };
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        return Err(RenderError::ImageSize {
            width: w,
            height: h,
        });
    }
    let pose = CameraPose {
        world_eye: eye,
        world_forward: fwd,
        world_up: up,
        fov_deg: fov,
        mirror_x: mirror,
    };
    Ok((pose, w, h))
}

/// Reads a `--camera-path` file with a clear error.
pub fn load_camera_path(
    path: &std::path::Path,
) -> Result<motu_abi::camera::RecordedPath, RenderError> {
    let text = std::fs::read_to_string(path).map_err(|source| RenderError::ReadCameraPath {
        path: path.to_path_buf(),
        source,
    })?;
    motu_abi::camera::RecordedPath::from_json(&text).map_err(|source| RenderError::CameraPath {
        path: path.to_path_buf(),
        source,
    })
}

/// The cameras of a recorded path: `frames` samples along it (`frames` ≤ 1: one per recorded
/// pose), at the path's recorded size when `path_size` and the path has one, else `camera`'s.
pub fn recorded_path_cameras(
    path: &RecordedPath,
    camera: &CameraParams,
    path_size: bool,
    frames: u32,
) -> Vec<CameraParams> {
    let (w, h) = match (path_size, path.width, path.height) {
        (true, Some(w), Some(h)) => (w, h),
        _ => (camera.width, camera.height),
    };
    let n = if frames <= 1 {
        path.poses.len() as u32
    } else {
        frames
    };
    (0..n).map(|f| path.sample(f, n).params(w, h)).collect()
}

/// The default camera animation of a streaming render: a sweep and dolly around the centre of
/// the root's bounds at the camera's distance from it.
pub fn sweep_around_root(view: &HierarchyView<'_>, pose: &CameraPose) -> CameraPath {
    let root = &view.tlases[view.root_tlas as usize];
    let centre = (Vec3::from_array(root.bounds_min) + Vec3::from_array(root.bounds_max)) * 0.5;
    CameraPath::sweep_and_dolly((centre - pose.world_eye).length(), 0.3)
}

#[cfg(test)]
mod tests;
