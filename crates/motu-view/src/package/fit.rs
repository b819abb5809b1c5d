//! A streaming budget that holds the whole scene draws the full build, as `motu render
//! --stream` does: the budget is tested against an upper bound of the full build's peak
//! (`motu_gpu::full_build_fits`, for the window's size); at or above it the full build is made
//! on the viewer's device, and a full build the allocator refuses after all falls back to
//! streaming, said. `--stream-always` skips the test.

use std::time::Instant;

use motu_abi::camera::CameraParams;
use motu_abi::HierarchyView;
use motu_render::stats::StreamFitStats;
use motu_render::{PackageMeshes, RenderError};

use super::{chain, PackageSourceSettings, SourceError};

/// The outcome of the test at the last rebuild and the frame size it counted.
#[derive(Clone, Debug)]
pub(super) struct Fit {
    /// `stream_fit` in `motu view --stats`.
    pub stats: StreamFitStats,
    /// The frame's pixels the bound counted.
    pixels: u64,
}

impl Fit {
    /// A full build drawn because it fitted, asked for a frame larger than the bound counted
    /// (a resized window): the budget must be tested again.
    pub fn outgrown(&self, camera: &CameraParams) -> bool {
        self.stats.full_build && u64::from(camera.width) * u64::from(camera.height) > self.pixels
    }
}

/// Tests whether the budget of `s` holds `view`'s full build at `size`; if so, builds it.
/// `None`: stream (the budget does not hold it, or the allocator refused the full build).
pub(super) fn full_build_if_it_fits(
    ctx: &motu_gpu::Context,
    view: &HierarchyView<'_>,
    meshes: &PackageMeshes<'_>,
    s: &PackageSourceSettings,
    (width, height): (u32, u32),
) -> Result<(Fit, Option<Box<motu_gpu::LiveRenderer>>), SourceError> {
    let blas_build = motu_gpu::BlasBuild::FastTrace;
    let t = Instant::now();
    let bound = tracing::info_span!("full_build_fits")
        .in_scope(|| {
            motu_gpu::full_build_fits(
                ctx,
                view,
                width,
                height,
                s.vram_budget_bytes.unwrap_or(u64::MAX),
                blas_build,
            )
        })
        .map_err(SourceError::Fit)?;
    let mut fit = Fit {
        stats: StreamFitStats {
            budget_bytes: bound.budget_bytes,
            full_build_upper_bytes: bound.upper_bytes,
            full_build: bound.fits(),
            check_ms: t.elapsed().as_secs_f64() * 1e3,
        },
        pixels: u64::from(width) * u64::from(height),
    };
    tracing::info!(
        budget_bytes = bound.budget_bytes,
        upper_bytes = bound.upper_bytes,
        fits = bound.fits(),
        ms = fit.stats.check_ms,
        "view: does the budget hold the full build?"
    );
    if !bound.fits() {
        return Ok((fit, None));
    }
    match motu_render::build_scene(
        ctx,
        view,
        meshes,
        s.vram_budget_bytes,
        s.max_allocations,
        blas_build,
        None,
    ) {
        Ok(scene) => {
            tracing::info!(
                budget_bytes = bound.budget_bytes,
                upper_bytes = bound.upper_bytes,
                "view --stream: the budget holds the whole scene: drawing the full build \
                 (--stream-always streams anyway)"
            );
            Ok((fit, Some(Box::new(motu_gpu::LiveRenderer::new(scene)))))
        }
        Err(e @ RenderError::BuildOverBudget { .. }) => {
            tracing::warn!(
                "view --stream: the full build did not fit after all ({}); streaming",
                chain(&e)
            );
            fit.stats.full_build = false;
            Ok((fit, None))
        }
        Err(e) => Err(e.into()),
    }
}
