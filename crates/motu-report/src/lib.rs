//! motu-report: the VRAM-budget report (`motu report`): what a compiled scene costs on a GPU
//! per element and as single-level vs multi-level, what fits a budget, and a ready `--subset`
//! list — as a terminal table ([`render_text`]), one JSON object ([`Report`] is `Serialize`)
//! and a self-contained HTML page ([`render_html`]).
//!
//! # Sizes
//! A [`SizeSource`] answers "how big is this BLAS/TLAS and its build scratch":
//! [`GpuSizes`] asks the driver (`vkGetAccelerationStructureBuildSizesKHR` through motu-gpu,
//! cached by shape), [`ModelSizes`] a model fitted on a real driver ([`LAVAPIPE`],
//! [`NVIDIA_H200`]; see [`Linear`]; data files in `presets/`, made by the `fit_sizes` example).
//! [`size_source_for_cli`] picks the driver and falls back to the model (`MOTU_REPORT_MODEL`).
//! Compacted sizes are a per-preset ratio until `--measure` builds structures (the hook is
//! [`SizeSource::compacted_blas_bytes`]). Everything but [`GpuSizes`] runs without a GPU.
//!
//! # What is counted ([`Cost`])
//! Geometry (positions, normals where stored, `u32` indices, AABB inputs), BLASes as built and
//! compacted, TLASes (AS + 64 B per instance), motu's record tables, build scratch; `resident`
//! = geometry + compacted BLAS + TLAS + instance buffers + tables; `peak` = resident + the
//! largest single build's transient + `render_overhead_bytes` (on what renders on its own:
//! variants, an element alone, a subset): frame buffers at the report's image size, the
//! staging ring and partly used allocator blocks under that budget, by the renderer's own
//! policy (`motu_gpu::full_build_overhead`) — so `peak` is a `--vram-budget` the full build
//! renders under (checked end to end in `tests/tests/report.rs`). A subset also pays for the
//! record tables `--subset` uploads whole (TLAS, BLAS, geometry, mesh, LOD records). Per element: nodes reached from one element's root
//! instances belong to it, nodes reached from several go to the `shared` row (and count once
//! per subset). Variants: as compiled, `--levels 2` and `sl` (see the `cost` module).
//!
//! # JSON (`motu report --json`)
//! One object, the fields of [`Report`]: `package`, `levels`, `sizes` ([`SizeSourceInfo`]:
//! `kind` `driver`|`model`, `device`, `preset`, `compaction`, `notes`), `max_instance_count`,
//! `max_primitive_count`, `unique_triangles`, `instanced_triangles`, `flattened_instances`,
//! `elements` ([`ElementReport`]: `name`, `id`, `kind` `element`|`untagged`|`shared`,
//! `root_instances`, `flattened_instances`, `instanced_triangles`, `unique_triangles`,
//! `meshes`, `ml` (a [`Cost`]), `sl_tlas_bytes`, `alone` (a [`Cost`] or null)), `variants`
//! ([`VariantReport`]: `name` `as_compiled`|`levels_2`|`sl`, `levels`, `top_instances`,
//! `top_tlas_pieces`, `exceeds_max_instance_count`, `cost`), `budget` ([`BudgetReport`] or
//! null: `budget_bytes`, `scene_fits`, `variants`/`elements` ([`Fit`]: `name`, `peak_bytes`,
//! `fits`), `suggestion` ([`SubsetSuggestion`]: `elements`, `subset_arg`, `cost`,
//! `instanced_triangles`, `triangle_fraction`, `method`), `streaming_fits`, `notes`),
//! `streaming` ([`StreamingReport`]), `render_overhead` (`motu_gpu::FullBuildOverhead`:
//! `frame_bytes`, `staging_bytes`, `allocator_slack_bytes`, `total_bytes`), `image_width`,
//! `image_height`, `warnings`. A [`Cost`] has `geometry_bytes`,
//! `blas_bytes`, `blas_compacted_bytes`, `tlas_bytes`, `instance_buffer_bytes`, `table_bytes`,
//! `build_scratch_peak_bytes`, `build_transient_peak_bytes`, `render_overhead_bytes`,
//! `resident_bytes`, `peak_bytes`,
//! `tlas_count`, `blas_count`, `instances`, `blas_triangles`.
//!
//! Module map, each file using only those before it: `human` (sizes and counts for people),
//! `sizes` (sources, curves, fitting), `presets` (the fitted models, loaded from
//! `presets/*.json`), `gpu` (driver sizes, the fitting harness), `cost` (per-node costs over
//! the BLAS counts, flattening), `owner` (ownership), `rows` (per-element and per-variant rows),
//! `budget` (what fits), `timing` (sources and phase timings), `streaming` (streaming rows, the
//! floor's size queries), `report` (assembly), `text`, `html`.
//!
//! # Map
//!
//! (The crate's code map; ARCHITECTURE.md keeps a summary.)
//! VRAM-budget report (text, JSON, self-contained HTML). Every peak it prints is a `--vram-budget`
//! the full build renders under: structures + largest build transient +
//! `motu_gpu::full_build_overhead` (frame buffers at the report's image size, the staging ring and
//! allocator slack, by the renderer's own budget policy in `motu-gpu/src/scene/budget.rs`); a
//! subset also pays for the record tables `--subset` uploads whole (`motu_abi::RootSubset` keeps
//! only the instance and PI records its root reaches). Fitted size models are data:
//! `presets/*.json` (loaded with `include_str!`), made by the `fit_sizes` example
//! (`presets/README.md`); `--measure` builds the package on the device through motu-render's
//! `PackageGeometry`.
//!
//! Key types: `build_report`, `ModelPreset`, `LAVAPIPE`, `NVIDIA_H200`.

mod budget;
mod cost;
mod gpu;
mod html;
mod human;
mod owner;
mod presets;
mod report;
mod rows;
mod sizes;
mod streaming;
mod text;
mod timing;

#[cfg(test)]
mod tests;

pub use budget::{BudgetReport, Fit, SubsetSuggestion, EXACT_LIMIT};
pub use cost::Cost;
pub use gpu::{
    fit_device, nearest_preset, preset_for_device, size_source_for_cli, DeviceFit, FittedCurve,
    GpuSizes, ENV_REPORT_MODEL, FIT_COUNTS,
};
pub use html::render_html;
pub use human::{format_size, human_bytes, human_count};
pub use presets::{preset, LAVAPIPE, NVIDIA_H200, PRESETS};
pub use report::{
    build_report, build_report_at, build_report_from_view, Report, ReportInput, DEFAULT_FLOOR_IMAGE,
};
pub use rows::{ElementReport, VariantReport};
pub use sizes::*;
pub use streaming::{StreamSplitReport, StreamingReport};
pub use text::render_text;
pub use timing::{PhaseTimings, Provenance, ReportSources};

/// Errors building a report.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    #[error(transparent)]
    Pack(#[from] motu_pack::PackError),
    #[error(transparent)]
    Hierarchy(#[from] motu_abi::HierarchyError),
    #[error("GPU size query failed: {0}")]
    Gpu(#[from] motu_gpu::GpuError),
    /// A report input out of range (the text says which and why).
    #[error("{0}")]
    Invalid(String),
    #[error(transparent)]
    Render(#[from] motu_render::RenderError),
    #[error("streaming floor: {0}")]
    Floor(#[source] motu_gpu::GpuError),
    #[error("persistent TLAS estimate: {0}")]
    PersistentEstimate(#[source] motu_gpu::GpuError),
    #[error("size preset: {0}")]
    Preset(#[source] serde_json::Error),
}
