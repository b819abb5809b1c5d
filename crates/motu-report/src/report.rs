//! Building a [`Report`] from a hierarchy: per-element costs, variants, budget and streaming.

use motu_abi::HierarchyView;
use serde::Serialize;

use crate::budget::BudgetReport;
use crate::cost::Cost;
use crate::rows::{ElementReport, VariantReport};
use crate::sizes::{SizeSource, SizeSourceInfo};
use crate::streaming::StreamingReport;
use crate::timing::{PhaseTimings, Provenance};
use crate::ReportError;
use motu_compile::blas_counts::BlasCounts;

mod build;
use build::build;

/// What the report needs besides the tables (a package's meta, or hand-made in tests).
#[derive(Clone, Debug, Default)]
pub struct ReportInput {
    /// Shown as the report's subject (the package path).
    pub package: String,
    /// How the package was compiled (`ml`, `sl`, a number).
    pub levels: String,
    /// Element names by element id.
    pub element_names: Vec<String>,
    /// Image size the streaming floor and every full-build peak are computed for (frame
    /// buffers scale with it).
    pub floor_image: (u32, u32),
}

/// Image size of the streaming floor when the package has no camera.
pub const DEFAULT_FLOOR_IMAGE: (u32, u32) = (640, 480);

// The GPU crate's reports as `motu_render::stats` writes them (their JSON keys live there).
fn overhead_json<S: serde::Serializer>(
    v: &motu_gpu::FullBuildOverhead,
    s: S,
) -> Result<S::Ok, S::Error> {
    motu_render::stats::FullBuildOverhead::from(v).serialize(s)
}

/// The VRAM-budget report (`motu report --json` prints it as one object).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Report {
    pub package: String,
    /// `levels` as compiled.
    pub levels: String,
    pub sizes: SizeSourceInfo,
    pub max_instance_count: u64,
    pub max_primitive_count: u64,
    pub unique_triangles: u64,
    pub instanced_triangles: u64,
    pub flattened_instances: u64,
    /// Elements in id order, then `untagged` (if any), then `shared`.
    pub elements: Vec<ElementReport>,
    /// `as_compiled`, `levels_2`, `sl`.
    pub variants: Vec<VariantReport>,
    pub budget: Option<BudgetReport>,
    pub streaming: StreamingReport,
    /// What the whole scene's full build needs besides its structures at the report's image
    /// size (`image_width × image_height`): the `render_overhead_bytes` of `as_compiled`.
    #[serde(serialize_with = "overhead_json")]
    pub render_overhead: motu_gpu::FullBuildOverhead,
    /// The image every peak and the streaming floor are computed for (`--width`/`--height`,
    /// else the package camera's).
    pub image_width: u32,
    pub image_height: u32,
    pub warnings: Vec<String>,
    /// Where the stored inputs came from and each phase's wall time (`sources`,
    /// `timings_ms`); not compared.
    #[serde(flatten)]
    pub provenance: Provenance,
}

impl Report {
    /// The variant named `name`.
    pub fn variant(&self, name: &str) -> Option<&VariantReport> {
        self.variants.iter().find(|v| v.name == name)
    }
    /// The as-compiled totals.
    pub fn total(&self) -> Cost {
        self.variant("as_compiled")
            .map(|v| v.cost)
            .unwrap_or_default()
    }
}

/// Builds the report for a package (see [`build_report_from_view`]); the streaming floor is
/// for the first camera's image size.
pub fn build_report(
    pkg: &motu_pack::ScenePackage,
    sizes: &dyn SizeSource,
    budget_bytes: Option<u64>,
) -> Result<Report, ReportError> {
    build_report_at(pkg, sizes, budget_bytes, None)
}

/// [`build_report`] with the streaming floor for `floor_image` (width, height; `None`: the
/// first camera's size, else [`DEFAULT_FLOOR_IMAGE`]).
pub fn build_report_at(
    pkg: &motu_pack::ScenePackage,
    sizes: &dyn SizeSource,
    budget_bytes: Option<u64>,
    floor_image: Option<(u32, u32)>,
) -> Result<Report, ReportError> {
    let meta = pkg.meta();
    let input = ReportInput {
        package: pkg.path().to_string(),
        levels: meta.levels.clone(),
        element_names: meta.elements.iter().map(|e| e.name.clone()).collect(),
        floor_image: floor_image.unwrap_or_else(|| {
            meta.cameras
                .first()
                .map_or(DEFAULT_FLOOR_IMAGE, |c| (c.width.max(1), c.height.max(1)))
        }),
    };
    let mut timings = PhaseTimings::default();
    let view = pkg.view()?;
    // The cap a streamed render of the package splits at by default: the one its import
    // recorded (`motu import --stream-split-instances`).
    let (cap, _) = motu_render::package_split_cap(pkg, None);
    let split = timings.time("stream_split_read", || {
        motu_render::stored_stream_split_or_none(pkg, &view, cap)
    })?;
    // The proxy clusters the import stored (checked TLAS by TLAS against the split hierarchy).
    let clusters = motu_render::stored_proxy_clusters(pkg);
    let counts = timings.time("blas_counts_read", || stored_blas_counts(pkg, &view));
    let stored = Stored {
        split,
        clusters,
        counts,
        cap: Some(cap),
        timings,
        references_checked: true,
    };
    build(&view, &input, sizes, budget_bytes, stored)
}

/// The package's BLAS counts (`blas_counts` section) where they are this view's; `None` (a
/// warning where a section was there) otherwise.
fn stored_blas_counts(
    pkg: &motu_pack::ScenePackage,
    view: &HierarchyView<'_>,
) -> Option<BlasCounts> {
    let bytes = match pkg.stored_blas_counts() {
        Ok(b) => b?,
        Err(e) => {
            tracing::warn!(error = %e, "the package's BLAS counts cannot be read; counted again");
            return None;
        }
    };
    let counts = motu_compile::blas_counts::decode_section(bytes, view);
    if counts.is_none() {
        tracing::warn!(
            "the package's BLAS counts are not a table this reader knows or not its \
             hierarchy's; counted again"
        );
    }
    counts
}

/// What a package stored for its readers: the stream split (`None`: split here), the proxy
/// clusters' section (`None`: made here), the BLAS counts (`None`: counted here) and the split
/// cap it recorded (`None`: [`motu_render::STREAM_SPLIT_INSTANCES`]); and the time spent
/// reading them.
#[derive(Default)]
struct Stored<'p> {
    split: Option<Option<motu_compile::StreamSplit>>,
    clusters: Option<&'p [u8]>,
    cap: Option<u32>,
    counts: Option<BlasCounts>,
    timings: PhaseTimings,
    /// The view passed `check_references` (a package's, when it was opened).
    references_checked: bool,
}

/// Builds the report from hierarchy tables. Sizes are asked of `sizes` for every BLAS and TLAS
/// (sources cache repeats). O(nodes × elements sharing them).
pub fn build_report_from_view(
    view: &HierarchyView<'_>,
    input: &ReportInput,
    sizes: &dyn SizeSource,
    budget_bytes: Option<u64>,
) -> Result<Report, ReportError> {
    build(view, input, sizes, budget_bytes, Stored::default())
}
