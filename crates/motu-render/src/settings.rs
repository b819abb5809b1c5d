//! What a render asks for (`motu render`'s flags as typed values) and what it reports back
//! while it runs.

use crate::{Backend, ShadingOptions, StreamBounds};
use motu_abi::lod::LodParams;

/// One render's settings: the backend, what it draws, the device and its budget, and for
/// `stream` the streaming bounds. The CLI maps its flags onto these one to one.
#[derive(Clone, Debug)]
pub struct RenderSettings {
    pub backend: Backend,
    pub view: motu_gpu::View,
    pub lod: LodParams,
    /// Traversal stack entries (`--stack-size`).
    pub stack_size: u32,
    /// TLAS walks a ray may make before it is cut short (`--max-traces-per-ray`).
    pub max_traces_per_ray: u32,
    /// Frames rendered (`--frames`): timed repeats, or the streaming sweep's length.
    pub frames: u32,
    pub shading: ShadingOptions,
    /// The camera by name (`--camera`) and the image size as given (`--width`, `--height`):
    /// streaming sizes its default sweep from them.
    pub camera_name: Option<String>,
    pub width: Option<u32>,
    pub height: Option<u32>,
    /// Vulkan device index (`--device`; `None`: `MOTU_DEVICE` or the first).
    pub device: Option<usize>,
    /// `--vram-budget` (`None`: what is free).
    pub vram_budget_bytes: Option<u64>,
    /// `--max-allocations` (`None`: the device's limit).
    pub max_allocations: Option<u32>,
    /// `--stream`: build only what rays touch, evicting under the budget.
    pub stream: bool,
    /// `--stream-max-passes` (`None`: sized from the scene).
    pub stream_max_passes: Option<u32>,
    pub stream_bounds: StreamBounds,
    /// `--allow-incomplete`: write a streamed frame with unfinished pixels (magenta).
    pub allow_incomplete: bool,
    /// `--allow-truncated`: write an image whose rays were cut short.
    pub allow_truncated: bool,
}

impl RenderSettings {
    /// The view's name (`--view`, the `--stats` key `view`).
    pub fn view_name(&self) -> &'static str {
        match self.view {
            motu_gpu::View::Shaded => "shaded",
            motu_gpu::View::Heatmap => "heatmap",
            motu_gpu::View::Lod => "lod",
            motu_gpu::View::Ids => "ids",
        }
    }
}

/// What a render reports while it runs, for the caller to print (the library prints nothing).
#[derive(Debug)]
pub enum RenderEvent<'a> {
    /// `--stream` renders one sample per pixel: `spp` above 1 is ignored.
    StreamSppIgnored { spp: u32 },
    /// A streamed frame finished (complete or not); an incomplete frame without fallback
    /// pixels is an error after this event unless `allow_incomplete`.
    StreamFrame {
        index: u32,
        stats: &'a motu_gpu::FrameStreamStats,
    },
    /// Rays were cut short and `allow_truncated` writes the image anyway: `what` says how many.
    TruncatedWritten { what: &'a str },
}
