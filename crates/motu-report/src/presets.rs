//! The built-in size models, loaded from data: `presets/NAME.json` beside this crate, written
//! by the `fit_sizes` example on each device (`presets/README.md` says how). Compaction is a
//! per-preset assumption until `--measure` builds structures (see the README).

use std::sync::LazyLock;

use crate::sizes::ModelPreset;

/// The data files, compiled in.
const LAVAPIPE_JSON: &str = include_str!("../presets/lavapipe.json");
const NVIDIA_H200_JSON: &str = include_str!("../presets/nvidia-h200.json");

fn load(json: &str) -> ModelPreset {
    // Compiled-in data, not user input: the crate's tests load and check every file.
    ModelPreset::from_json(json).unwrap_or_else(|e| panic!("built-in size preset: {e}"))
}

/// llvmpipe (Mesa 25.0.7, LLVM 15.0.6), the CI device: it sizes structures exactly, so its
/// compaction ratio is 1.0.
pub static LAVAPIPE: LazyLock<ModelPreset> = LazyLock::new(|| load(LAVAPIPE_JSON));

/// NVIDIA H200 (driver 580.159.04); its compaction ratio is an assumption (see the README).
pub static NVIDIA_H200: LazyLock<ModelPreset> = LazyLock::new(|| load(NVIDIA_H200_JSON));

/// Every built-in preset.
pub static PRESETS: std::sync::LazyLock<[&'static ModelPreset; 2]> =
    std::sync::LazyLock::new(|| [&*LAVAPIPE, &*NVIDIA_H200]);

/// Finds a preset by name (`lavapipe`, `nvidia-h200`).
pub fn preset(name: &str) -> Option<&'static ModelPreset> {
    PRESETS
        .iter()
        .copied()
        .find(|p| p.name.eq_ignore_ascii_case(name))
}

#[cfg(test)]
mod tests;
