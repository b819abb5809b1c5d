//! The error type of `motu bench` and its constructors.

use std::path::PathBuf;

/// What went wrong in a benchmark run (a failing step is a recorded result, not an error).
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// Bad options; the text names the option and the value.
    #[error("{0}")]
    Options(String),
    #[error("{what}")]
    Io {
        what: String,
        #[source]
        source: std::io::Error,
    },
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    #[error("{what}")]
    Gpu {
        what: &'static str,
        #[source]
        source: motu_gpu::GpuError,
    },
    #[error("{what}")]
    Trace {
        what: &'static str,
        #[source]
        source: motu_trace::TraceError,
    },
    #[error(transparent)]
    TraceFrame(motu_trace::TraceError),
    #[error("{what}")]
    PngWrite {
        what: String,
        #[source]
        source: motu_trace::TraceError,
    },
    #[error("{what}")]
    GpuFrame {
        what: String,
        #[source]
        source: motu_gpu::GpuError,
    },
    #[error(transparent)]
    Devices(motu_gpu::GpuError),
    #[error("{what}")]
    Package {
        what: String,
        #[source]
        source: motu_pack::PackError,
    },
    #[error(transparent)]
    PackageData(motu_pack::PackError),
    #[error(transparent)]
    Render(#[from] motu_render::RenderError),
    #[error("every configuration failed (first: {first}); logs in {}", logs.display())]
    EveryConfigurationFailed { first: String, logs: PathBuf },
}

/// `return Err(BenchError::Options(format!(..)))`: an options error, the way anyhow's `bail!` reads.
macro_rules! bail {
    ($($t:tt)*) => {
        return Err(BenchError::Options(format!($($t)*)))
    };
}

pub(crate) fn io(what: String) -> impl FnOnce(std::io::Error) -> BenchError {
    move |source| BenchError::Io { what, source }
}

/// `what` failed on the GPU: a renderer's error or the device layer's (re-exported by motu-gpu).
pub(crate) fn gpu_err<E: Into<motu_gpu::GpuError>>(
    what: &'static str,
) -> impl FnOnce(E) -> BenchError {
    move |source| BenchError::Gpu {
        what,
        source: source.into(),
    }
}
