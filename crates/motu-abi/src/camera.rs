//! The camera model shared by every backend: the renderer computes [`CameraParams`] once per
//! frame and both the CPU oracle and the shaders derive primary rays from it with the same
//! formula ([`CameraParams::primary_dir`], mirrored in `shaders/camera.glsl`).

use bytemuck::{Pod, Zeroable};
use glam::Vec3;

/// pbrt semantics: `fov_deg` spans the shorter image axis; raster y grows downwards; the image
/// x axis is `cross(up, forward)` (pbrt's left-handed camera space) unless `mirror_x` (pbrt's
/// `Scale -1 1 1` before `LookAt`) flips it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct CameraParams {
    pub world_eye: [f32; 3],
    pub width: u32,
    /// Direction (unnormalised) through the top-left corner of the image.
    pub world_dir00: [f32; 3],
    pub height: u32,
    /// Step per pixel to the right.
    pub world_du: [f32; 3],
    /// Pixels per world unit at distance 1 (`height / (2 tan(fov_y / 2))`), for LOD.
    pub pixels_per_unit_at_1: f32,
    /// Step per pixel downwards.
    pub world_dv: [f32; 3],
    pub _pad: u32,
}

impl CameraParams {
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        eye: Vec3,
        forward: Vec3,
        up: Vec3,
        fov_deg: f32,
        mirror_x: bool,
        width: u32,
        height: u32,
    ) -> Self {
        let (w, h) = (width.max(1) as f32, height.max(1) as f32);
        let aspect = w / h;
        let (sx, sy) = if aspect > 1.0 {
            (aspect, 1.0)
        } else {
            (1.0, 1.0 / aspect)
        };
        let tan_half = (fov_deg.to_radians() * 0.5).tan();
        let fwd = forward.normalize_or(Vec3::NEG_Z);
        let mut right = up.cross(fwd).normalize_or(Vec3::X);
        if mirror_x {
            right = -right;
        }
        // Re-orthogonalise up against the (possibly mirrored) right.
        let up = fwd.cross(right).normalize_or(Vec3::Y) * if mirror_x { -1.0 } else { 1.0 };
        let dir00 = fwd - right * (sx * tan_half) + up * (sy * tan_half);
        let du = right * (2.0 * sx * tan_half / w);
        let dv = -up * (2.0 * sy * tan_half / h);
        let tan_y = sy * tan_half;
        Self {
            world_eye: eye.to_array(),
            width,
            world_dir00: dir00.to_array(),
            height,
            world_du: du.to_array(),
            pixels_per_unit_at_1: h / (2.0 * tan_y),
            world_dv: dv.to_array(),
            _pad: 0,
        }
    }

    /// The camera one more step along the motion from `prev` to `self` (eye and image plane
    /// moved by the same difference again; same size): a guess of the next frame's camera
    /// for prefetching, not an exact pose.
    pub fn extrapolated_from(&self, prev: &CameraParams) -> CameraParams {
        let step =
            |a: [f32; 3], b: [f32; 3]| (Vec3::from_array(a) * 2.0 - Vec3::from_array(b)).to_array();
        CameraParams {
            world_eye: step(self.world_eye, prev.world_eye),
            world_dir00: step(self.world_dir00, prev.world_dir00),
            world_du: step(self.world_du, prev.world_du),
            world_dv: step(self.world_dv, prev.world_dv),
            ..*self
        }
    }

    /// Normalised world direction through pixel `(x, y)` at sub-pixel offset `(ox, oy)`
    /// (0.5, 0.5 = centre).
    #[inline]
    pub fn primary_dir(&self, x: u32, y: u32, ox: f32, oy: f32) -> Vec3 {
        let d = Vec3::from_array(self.world_dir00)
            + Vec3::from_array(self.world_du) * (x as f32 + ox)
            + Vec3::from_array(self.world_dv) * (y as f32 + oy);
        d.normalize()
    }
}

/// A camera as the user states it (before the image size is known): what a camera path moves.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraPose {
    pub world_eye: Vec3,
    /// Viewing direction (need not be normalised).
    pub world_forward: Vec3,
    pub world_up: Vec3,
    pub fov_deg: f32,
    pub mirror_x: bool,
}

impl CameraPose {
    /// The frame camera for a `width × height` image.
    pub fn params(&self, width: u32, height: u32) -> CameraParams {
        CameraParams::new(
            self.world_eye,
            self.world_forward,
            self.world_up,
            self.fov_deg,
            self.mirror_x,
            width,
            height,
        )
    }
}

/// How [`camera_path`] moves a camera over the frames.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraPath {
    /// Total yaw about the up vector, swept linearly from `-sweep/2` (first frame) to
    /// `+sweep/2` (last frame).
    pub yaw_sweep_deg: f32,
    /// World distance the eye travels along the (yawed) viewing direction by the last frame.
    pub dolly_world: f32,
}

impl CameraPath {
    /// A 40° sweep and a dolly of `fraction` of `distance` (e.g. the eye's distance to the
    /// scene's centre), so a path sees different parts of a scene and moves into it.
    pub fn sweep_and_dolly(distance: f32, fraction: f32) -> Self {
        Self {
            yaw_sweep_deg: 40.0,
            dolly_world: (distance * fraction).max(0.0),
        }
    }
}

/// Frame `frame` of `frame_count` along `path` from `base`: deterministic (pure f32 arithmetic
/// on the inputs), so the CPU oracle and the GPU render the same frames. A single-frame path
/// is `base` itself.
pub fn camera_path(
    base: &CameraPose,
    path: &CameraPath,
    frame: u32,
    frame_count: u32,
) -> CameraPose {
    if frame_count <= 1 {
        return *base;
    }
    let s = frame.min(frame_count - 1) as f32 / (frame_count - 1) as f32;
    let yaw = (path.yaw_sweep_deg * (s - 0.5)).to_radians();
    let up = base.world_up.normalize_or(Vec3::Y);
    let forward =
        glam::Quat::from_axis_angle(up, yaw) * base.world_forward.normalize_or(Vec3::NEG_Z);
    CameraPose {
        world_eye: base.world_eye + forward * (path.dolly_world * s),
        world_forward: forward,
        ..*base
    }
}

/// A recorded camera flight (`motu view --record`): one pose per frame, replayed by
/// `motu render --camera-path`, `motu view --camera-path` and `motu bench --camera-path`.
///
/// JSON form (`format` and `version` are checked; sizes are optional hints):
/// `{"format": "motu-camera-path", "version": 1, "width": 640, "height": 480,
///   "frames": [{"eye": [x, y, z], "forward": [x, y, z], "up": [x, y, z], "fov_deg": 45.0,
///   "mirror_x": false}, ...]}`
#[derive(Clone, Debug, PartialEq)]
pub struct RecordedPath {
    pub poses: Vec<CameraPose>,
    pub width: Option<u32>,
    pub height: Option<u32>,
}

/// Why a camera-path file was rejected.
#[derive(Debug, thiserror::Error)]
pub enum PathError {
    #[error("not a camera path: {0}")]
    Json(#[from] serde_json::Error),
    #[error("not a camera path: `format` is {0:?}, expected \"motu-camera-path\"")]
    Format(String),
    #[error("camera path version {0} is not supported (this motu reads version 1)")]
    Version(u32),
    #[error("the camera path has no frames")]
    Empty,
    #[error("frame {frame}: {what}")]
    Frame { frame: usize, what: String },
    #[error("`width`/`height` must be 1 to 16384 (got {0}×{1})")]
    Size(u32, u32),
}

pub const CAMERA_PATH_FORMAT: &str = "motu-camera-path";

#[derive(serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct PathFile {
    format: String,
    version: u32,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    width: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    height: Option<u32>,
    frames: Vec<PoseJson>,
}

#[derive(serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct PoseJson {
    eye: [f32; 3],
    forward: [f32; 3],
    up: [f32; 3],
    fov_deg: f32,
    #[serde(default)]
    mirror_x: bool,
}

impl RecordedPath {
    /// The JSON form (f32 values print exactly: a written path replays bit-identically).
    pub fn to_json(&self) -> String {
        let f = PathFile {
            format: CAMERA_PATH_FORMAT.into(),
            version: 1,
            width: self.width,
            height: self.height,
            frames: self
                .poses
                .iter()
                .map(|p| PoseJson {
                    eye: p.world_eye.to_array(),
                    forward: p.world_forward.to_array(),
                    up: p.world_up.to_array(),
                    fov_deg: p.fov_deg,
                    mirror_x: p.mirror_x,
                })
                .collect(),
        };
        serde_json::to_string_pretty(&f).unwrap_or_default()
    }

    /// Parses and validates the JSON form (errors carry line and column, or the frame).
    pub fn from_json(text: &str) -> Result<RecordedPath, PathError> {
        let f: PathFile = serde_json::from_str(text)?;
        if f.format != CAMERA_PATH_FORMAT {
            return Err(PathError::Format(f.format));
        }
        if f.version != 1 {
            return Err(PathError::Version(f.version));
        }
        if f.frames.is_empty() {
            return Err(PathError::Empty);
        }
        if let (Some(w), Some(h)) = (f.width.or(Some(1)), f.height.or(Some(1))) {
            if !(1..=16384).contains(&w) || !(1..=16384).contains(&h) {
                return Err(PathError::Size(w, h));
            }
        }
        let mut poses = Vec::with_capacity(f.frames.len());
        for (i, p) in f.frames.iter().enumerate() {
            let bad = |what: String| PathError::Frame { frame: i, what };
            let finite = |v: &[f32]| v.iter().all(|x| x.is_finite());
            if !finite(&p.eye) || !finite(&p.forward) || !finite(&p.up) || !p.fov_deg.is_finite() {
                return Err(bad("a value is not a finite number".into()));
            }
            let (fwd, up) = (Vec3::from_array(p.forward), Vec3::from_array(p.up));
            if fwd.length() < 1e-12 {
                return Err(bad("`forward` is the zero vector".into()));
            }
            if fwd.normalize().cross(up.normalize_or_zero()).length() < 1e-6 {
                return Err(bad("`up` is zero or parallel to `forward`".into()));
            }
            if !(p.fov_deg > 0.0 && p.fov_deg < 180.0) {
                return Err(bad(format!("`fov_deg` {} is outside (0, 180)", p.fov_deg)));
            }
            poses.push(CameraPose {
                world_eye: Vec3::from_array(p.eye),
                world_forward: fwd,
                world_up: up,
                fov_deg: p.fov_deg,
                mirror_x: p.mirror_x,
            });
        }
        Ok(RecordedPath {
            poses,
            width: f.width,
            height: f.height,
        })
    }

    /// Frame `frame` of `frame_count` spread over the recording: the recorded poses themselves
    /// when `frame_count` equals their number, else linear interpolation between the two
    /// nearest (pure f32 arithmetic: every replayer gets the same pose).
    pub fn sample(&self, frame: u32, frame_count: u32) -> CameraPose {
        let n = self.poses.len();
        if n == 1 || frame_count <= 1 {
            return self.poses[0];
        }
        if frame_count as usize == n {
            return self.poses[(frame as usize).min(n - 1)];
        }
        let t = frame.min(frame_count - 1) as f32 / (frame_count - 1) as f32 * (n - 1) as f32;
        let i = (t.floor() as usize).min(n - 2);
        let s = t - i as f32;
        let (a, b) = (&self.poses[i], &self.poses[i + 1]);
        CameraPose {
            world_eye: a.world_eye.lerp(b.world_eye, s),
            world_forward: a
                .world_forward
                .normalize()
                .lerp(b.world_forward.normalize(), s)
                .normalize_or(a.world_forward),
            world_up: a.world_up.lerp(b.world_up, s).normalize_or(a.world_up),
            fov_deg: a.fov_deg + (b.fov_deg - a.fov_deg) * s,
            mirror_x: a.mirror_x,
        }
    }
}

#[cfg(test)]
mod tests;
