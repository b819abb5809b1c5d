//! SPIR-V of every GLSL shader under `shaders/`, compiled and validated by `build.rs`.
//! A file `shaders/foo/bar.rgen` becomes `FOO_BAR_RGEN: &[u32]`.

/// One embedded shader.
#[derive(Clone, Copy, Debug)]
pub struct EmbeddedShader {
    /// Path relative to `shaders/`.
    pub path: &'static str,
    /// The file extension: `comp`, `rgen`, `rchit`, `rahit`, `rint` or `rmiss`.
    pub stage: &'static str,
    pub words: &'static [u32],
}

include!(concat!(env!("OUT_DIR"), "/shaders.rs"));

#[cfg(test)]
mod tests;
