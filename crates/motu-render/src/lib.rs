//! Render set-up shared by `motu render`, `motu view` and `motu bench`: a package's meshes for
//! the tracers, the camera (by name, the scene's, or a view of the bounds) and recorded camera
//! paths, the LOD mode (instance or traversal, and why) and the CPU reference with instance LOD, the scene's shading (lights, sky, the AO distance), and the streaming bounds. The CLI
//! maps its flags onto these types and prints; no Vulkan here (that is `motu-gpu`).

mod camera;
mod cpu;
mod lod;
mod meshes;
mod shading;
mod stream;

pub use camera::{
    camera_params, camera_pose, load_camera_path, recorded_path_cameras, sweep_around_root,
};
pub use cpu::render_cpu_instance_lod;
pub use lod::{choose_lod_mode, LodChoice, LodMode};
pub use meshes::PackageMeshes;
pub use shading::{scene_shading, ShadingOptions, AO_DISTANCE_OF_DIAGONAL};
pub use stream::StreamBounds;

use std::path::PathBuf;

/// What went wrong setting up a render.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// `--camera NAME` names no camera of the scene.
    #[error("no camera named '{name}': the scene has {}", if known.is_empty() { "none".to_string() } else { known.join(", ") })]
    NoCamera { name: String, known: Vec<String> },
    #[error("image size {width}×{height} is out of range (1–16384 per side)")]
    ImageSize { width: u32, height: u32 },
    #[error("reading camera path {}", path.display())]
    ReadCameraPath {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{what}")]
    Cpu {
        what: &'static str,
        #[source]
        source: motu_trace::TraceError,
    },
    #[error("no frame rendered")]
    NoFrame,
    #[error("rewriting LOD selectors as instances")]
    InstanceLod(#[source] motu_abi::HierarchyError),
    #[error("camera path {}", path.display())]
    CameraPath {
        path: PathBuf,
        #[source]
        source: motu_abi::camera::PathError,
    },
}
