//! The per-frame bounds of the streaming renderer (`--stream-fallback`, `--stream-build-budget`,
//! `--stream-build-ms`).

/// What one streaming frame may build, and what it shows for what it did not build.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StreamBounds {
    pub fallback: motu_gpu::StreamFallback,
    /// Bytes one frame may build (`None`: unbounded).
    pub frame_build_bytes: Option<u64>,
    /// Milliseconds of building one frame may spend (`None`: unbounded).
    pub frame_build_ms: Option<f64>,
}

impl StreamBounds {
    /// The streaming options with these bounds (the rest default).
    pub fn options(&self) -> motu_gpu::StreamOptions {
        motu_gpu::StreamOptions {
            fallback: self.fallback,
            frame_build_bytes: self.frame_build_bytes.unwrap_or(0),
            frame_build_ms: self.frame_build_ms.unwrap_or(0.0),
            ..Default::default()
        }
    }

    /// Whether any bound is set (they need streaming).
    pub fn given(&self) -> bool {
        self.fallback != motu_gpu::StreamFallback::Off
            || self.frame_build_bytes.is_some()
            || self.frame_build_ms.is_some()
    }
}
