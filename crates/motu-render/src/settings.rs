//! What a render asks for (`motu render`'s flags as typed values) and what it reports back
//! while it runs.

use crate::{Backend, ShadingOptions, StreamBounds};
use motu_abi::aov::Aov;
use motu_abi::lod::LodParams;

/// One render's settings: the backend, what it draws, the device and its budget, and for
/// `stream` the streaming bounds. The CLI maps its flags onto these one to one.
#[derive(Clone, Debug)]
pub struct RenderSettings {
    pub backend: Backend,
    pub view: motu_gpu::View,
    pub lod: LodParams,
    pub limits: TraversalLimits,
    /// Frames rendered (`--frames`): timed repeats, or the streaming sweep's length.
    pub frames: u32,
    pub shading: ShadingOptions,
    pub camera: CameraRequest,
    pub device: DeviceRequest,
    /// `--stream`: build only what rays touch, evicting under the budget (`None`: a full build).
    pub stream: Option<StreamSettings>,
    /// `--denoise`: the shaded image is filtered ([`crate::denoise`]); the AOV never is.
    pub denoise: bool,
}

/// How far a ray's traversal may go (`--stack-size`, `--max-traces-per-ray`), and whether an
/// image with rays cut short is written anyway (`--allow-truncated`).
#[derive(Clone, Copy, Debug)]
pub struct TraversalLimits {
    pub stack_size: u32,
    pub max_traces_per_ray: u32,
    pub allow_truncated: bool,
}

/// The camera by name (`--camera`) and the image size as given (`--width`, `--height`):
/// streaming sizes its default sweep from them.
#[derive(Clone, Debug, Default)]
pub struct CameraRequest {
    pub name: Option<String>,
    pub width: Option<u32>,
    pub height: Option<u32>,
}

/// The Vulkan device (`--device`; `None`: `MOTU_DEVICE` or the first) and its limits:
/// `--vram-budget` (`None`: what is free) and `--max-allocations` (`None`: the device's).
#[derive(Clone, Copy, Debug, Default)]
pub struct DeviceRequest {
    pub index: Option<usize>,
    pub vram_budget_bytes: Option<u64>,
    pub max_allocations: Option<u32>,
    /// `--blas-build` (`None`: fast trace for a full build, small when streaming).
    pub blas_build: Option<motu_gpu::BlasBuild>,
    /// `--pipeline-stats`: capture the driver's statistics of every pipeline made
    /// (`pipeline_executables` in `--stats`; a device without the extension warns).
    pub pipeline_stats: bool,
}

/// `--stream`'s own settings: the pass cap (`--stream-max-passes`; `None`: sized from the
/// scene), the per-frame bounds, and whether a frame with unfinished pixels is written
/// (magenta) anyway (`--allow-incomplete`).
#[derive(Clone, Debug, Default)]
pub struct StreamSettings {
    pub max_passes: Option<u32>,
    pub bounds: StreamBounds,
    pub allow_incomplete: bool,
    /// Where built structures are kept for reuse (`--host-cache`, `--as-cache`).
    pub cache: crate::CacheSettings,
    /// `--stream-always`: stream even when the budget holds the whole scene (by default the
    /// full build renders it then: never slower).
    pub always: bool,
}

impl RenderSettings {
    /// How BLASes are built: `--blas-build`, else small when streaming (the budget binds and
    /// frames are mostly building) and fast trace for a full build (the frame is all tracing).
    pub fn blas_build(&self) -> motu_gpu::BlasBuild {
        self.device.blas_build.unwrap_or(if self.stream.is_some() {
            motu_gpu::BlasBuild::Small
        } else {
            motu_gpu::BlasBuild::FastTrace
        })
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
    /// `--stream` under a budget that holds the whole scene: the full build renders it.
    StreamFullBuild { budget_bytes: u64, upper_bytes: u64 },
    /// The full build chosen for `--stream` did not fit after all (`what`): streamed instead.
    StreamFullBuildRefused { what: &'a str },
    /// A streamed render's final image (no denoising or check left to change or refuse it),
    /// before the streamer writes its structures to the cache directory for the next process
    /// (`persist_cache`, seconds at scale): the caller may write it now. The same image comes
    /// back in [`Rendered`](crate::Rendered).
    Image { aov: &'a Aov, rgba8: &'a [u8] },
}
