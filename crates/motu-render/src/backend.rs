//! Which tracer renders: the CPU reference or one of the GPU's traversal-shader backends.

/// A render backend (`--backend`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Backend {
    /// The ray-tracing pipeline (every RT device; the only one on the H200).
    Pipeline,
    /// A compute shader with ray queries.
    Query,
    /// The CPU reference traversal.
    Cpu,
}

impl Backend {
    /// The name `--backend` and the `--stats` key `backend` use.
    pub fn name(self) -> &'static str {
        match self {
            Backend::Pipeline => "pipeline",
            Backend::Query => "query",
            Backend::Cpu => "cpu",
        }
    }

    /// The GPU backend (`None` for the CPU).
    pub fn gpu(self) -> Option<motu_gpu::Backend> {
        match self {
            Backend::Pipeline => Some(motu_gpu::Backend::Pipeline),
            Backend::Query => Some(motu_gpu::Backend::Query),
            Backend::Cpu => None,
        }
    }
}

/// `query` where a device has ray queries (usually fastest on RTX), else `pipeline`, else the CPU.
pub fn best_backend(devices: &[motu_gpu::DeviceReport]) -> Backend {
    if devices.iter().any(|d| d.ray_query) {
        Backend::Query
    } else if devices.iter().any(|d| d.ray_pipeline) {
        Backend::Pipeline
    } else {
        Backend::Cpu
    }
}
