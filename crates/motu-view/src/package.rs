//! The viewer's frame source over a package: a full GPU build (with instance-level LOD where the
//! rule allows it) or the streaming renderer under a budget, rebuilt when the element set or
//! the LOD mode changes. A streaming budget that holds the whole scene gets the full build
//! instead (`fit.rs`, as `motu render --stream`). `motu view` maps its flags onto
//! [`PackageSourceSettings`].

mod fit;

use crate::{FrameSource, SourceFrame, SourceStats, ViewOptions};
use motu_abi::camera::{CameraParams, CameraPose};
use motu_abi::lod::LodParams;
use motu_abi::{HierarchyView, RootSubset};
use motu_gpu::MeshBlobSource as _;
use motu_pack::ScenePackage;
use motu_render::stats::ViewDetail;
use motu_render::{
    choose_lod_mode, LodMode, PackageMeshes, RenderError, StreamBounds, INTERACTIVE_BUILD_MS,
};

/// How the package source renders (`motu view`'s flags, typed).
#[derive(Clone, Debug)]
pub struct PackageSourceSettings {
    /// The Vulkan device (`--device`); `None`: the first that can present and trace.
    pub device_index: Option<usize>,
    pub backend: motu_gpu::Backend,
    /// `--vram-budget`: the full build's budget, or the streaming budget.
    pub vram_budget_bytes: Option<u64>,
    /// `--max-allocations`: overrides the device's allocation count limit.
    pub max_allocations: Option<u32>,
    /// Streaming (`--stream` or `--vram-budget`); `None`: one full build.
    pub stream: Option<ViewStreamSettings>,
}

/// The streaming renderer's settings in the viewer.
#[derive(Clone, Debug, Default)]
pub struct ViewStreamSettings {
    /// `--stream-fallback`, `--stream-build-budget`, `--stream-build-ms`.
    pub bounds: StreamBounds,
    /// `--stream-passes`: the build–trace passes one frame may take.
    pub max_passes: Option<u32>,
    /// `--frames` as given: a scripted run of that many frames; `None`: flying (a replayed
    /// camera path without `--frames` too).
    pub frames: Option<u32>,
    /// `--host-cache`, `--as-cache`, `--no-as-cache`: where built structures are kept between
    /// evictions and processes (as `motu render --stream`).
    pub cache: motu_render::CacheSettings,
    /// `--stream-always`: stream even when the budget holds the whole scene (by default the
    /// full build draws it then, as `motu render --stream` does).
    pub always: bool,
}

impl ViewStreamSettings {
    /// Whether streaming frames are progressive (one trace with what is resident, then a build
    /// bounded by the frame budget for the next frame): `--stream-passes 1`, or flying without
    /// `--stream-passes`.
    pub fn progressive(&self) -> bool {
        self.max_passes == Some(1) || (self.frames.is_none() && self.max_passes.is_none())
    }

    /// The streaming renderer's options under `budget_bytes`.
    fn options(&self, budget_bytes: u64, max_allocations: Option<u32>) -> motu_gpu::StreamOptions {
        let opts = motu_gpu::StreamOptions {
            budget_bytes,
            // Interactive: bounded build work per frame keeps the window responsive;
            // the next frames go on refining (what was built stays resident).
            max_passes: self
                .max_passes
                .unwrap_or(motu_gpu::StreamOptions::default().max_passes),
            max_allocations: max_allocations
                .unwrap_or(motu_gpu::StreamOptions::default().max_allocations),
            ..self.bounds.options()
        };
        motu_gpu::StreamOptions {
            // Flying with no build budget given: one frame's worth of building per
            // frame, so the window stays responsive while structures arrive.
            frame_build_ms: if self.progressive() && self.bounds.build_unbounded() {
                INTERACTIVE_BUILD_MS
            } else {
                opts.frame_build_ms
            },
            ..opts
        }
    }
}

/// The scene's cameras as poses for the number keys, in the package's order.
pub fn scene_cameras(
    pkg: &ScenePackage,
    base: &HierarchyView<'_>,
) -> Result<Vec<(String, CameraPose)>, RenderError> {
    pkg.meta()
        .cameras
        .iter()
        .map(|c| {
            let (p, _, _) = motu_render::camera_pose(pkg, base, Some(&c.name), Some(1), Some(1))?;
            Ok((c.name.clone(), p))
        })
        .collect()
}

/// The fly speed when none is given, in world units per second: a quarter of the radius of the
/// root's bounds.
pub fn default_fly_speed(base: &HierarchyView<'_>) -> f32 {
    let root = &base.tlases[base.root_tlas as usize];
    let radius = ((glam::Vec3::from_array(root.bounds_max)
        - glam::Vec3::from_array(root.bounds_min))
    .length()
        * 0.5)
        .max(1e-3);
    radius * 0.25
}

/// What went wrong opening or rendering the package source. [`chain`] gives the message the
/// viewer shows (each cause after a colon).
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    #[error("opening a Vulkan device that can present: {0}")]
    Device(motu_gpu::GpuError),
    #[error("filtering the root for the element set")]
    Subset(#[source] motu_abi::HierarchyError),
    #[error(transparent)]
    Render(#[from] RenderError),
    #[error("setting up streaming (the resident skeleton must fit the budget)")]
    StreamSetup(#[source] motu_gpu::GpuError),
    #[error("testing whether the budget holds the full build")]
    Fit(#[source] motu_gpu::GpuError),
    #[error("rendering on the GPU")]
    Gpu(#[source] motu_gpu::GpuError),
    #[error("streaming a frame")]
    StreamFrame(#[source] motu_gpu::GpuError),
    #[error("no renderer (an earlier rebuild failed)")]
    NoRenderer,
}

/// `e` and its causes, joined by `: `.
pub fn chain(e: &dyn std::error::Error) -> String {
    let mut msg = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        msg.push_str(&format!(": {c}"));
        cause = c.source();
    }
    msg
}

/// The renderer drawing the current structures; `None` after a failed rebuild.
enum Renderer<'p> {
    Full(Option<Box<motu_gpu::LiveRenderer>>),
    Stream(Option<Box<motu_gpu::StreamingRenderer<'p>>>),
}

/// A [`FrameSource`] over a package's hierarchy: the device, the structures for the element set
/// and LOD mode shown, and the renderer drawing them.
pub struct PackageSource<'p> {
    ctx: motu_gpu::Context,
    /// The package's hierarchy (what a full build draws).
    base: HierarchyView<'p>,
    /// Streaming: `base` with large TLASes split into pieces, made at the first streamed build
    /// (a budget that holds the scene never needs it).
    split_base: Option<HierarchyView<'p>>,
    meshes: &'p PackageMeshes<'p>,
    element_ids: Vec<u32>,
    /// The element set the renderer was built for.
    built_for: Vec<bool>,
    /// The LOD mode asked for when the renderer was built (instance where the rule allows it)
    /// with the LOD parameters it was decided for, and the mode that ran.
    built_lod: Option<(bool, LodParams)>,
    lod_mode: &'static str,
    renderer: Renderer<'p>,
    settings: PackageSourceSettings,
    /// The camera of the previous streamed frame: a moving camera's next one is extrapolated
    /// from it for the streaming probe (prefetch).
    prev_camera: Option<CameraParams>,
    total_structures: u64,
    /// Each source mesh's base colour (the denoiser's guide).
    base_colours: std::collections::HashMap<u32, [f32; 3]>,
    /// A material has a base-colour texture (the guide renders the albedo view).
    textured: bool,
    /// Streaming: whether the budget held the full build at the last rebuild (`None` without
    /// streaming or with `--stream-always`).
    stream_fit: Option<fit::Fit>,
}

impl<'p> PackageSource<'p> {
    /// Opens a device that can present on `o.display` and builds the structures for
    /// `o.elements_on` (`element_ids`: the package's element ids in the same order) and
    /// `o`'s LOD mode.
    pub fn open(
        o: &ViewOptions,
        base: HierarchyView<'p>,
        meshes: &'p PackageMeshes<'p>,
        element_ids: Vec<u32>,
        settings: PackageSourceSettings,
    ) -> Result<PackageSource<'p>, SourceError> {
        let ctx = motu_gpu::Context::new(&motu_gpu::ContextOptions {
            device_index: settings.device_index,
            limit_overrides: motu_gpu::LimitOverrides {
                max_memory_allocation_count: settings.max_allocations,
                ..Default::default()
            },
            require: match settings.backend {
                motu_gpu::Backend::Query => motu_gpu::Requirement::RayQuery,
                motu_gpu::Backend::Pipeline => motu_gpu::Requirement::RayPipeline,
            },
            presentation: o.display,
            ..Default::default()
        })
        .map_err(|e| SourceError::Device(e.into()))?;
        let mut src = PackageSource {
            ctx,
            base,
            split_base: None,
            meshes,
            element_ids,
            built_for: Vec::new(),
            built_lod: None,
            lod_mode: "",
            renderer: Renderer::Full(None),
            total_structures: (base.blases.len() + base.tlases.len()) as u64,
            settings,
            prev_camera: None,
            base_colours: motu_render::denoise::mesh_base_colours(&base),
            textured: motu_render::denoise::has_textured_materials(&base),
            stream_fit: None,
        };
        let size = (o.width.max(1), o.height.max(1));
        src.rebuild(&o.elements_on, o.lod_instance, &o.render.lod, size)?;
        Ok(src)
    }

    /// Streaming renders large TLASes split into pieces (as `motu render --stream`, from the
    /// split the import stored when `base` is the package's own); the split tables are made
    /// once and live as long as the viewer (leaked: the renderer and every element subset
    /// borrow them).
    fn split_base(
        &mut self,
        stream: &ViewStreamSettings,
    ) -> Result<HierarchyView<'p>, SourceError> {
        if let Some(b) = self.split_base {
            return Ok(b);
        }
        let pkg = self.meshes.0;
        let (cap, _) = motu_render::package_split_cap(pkg, stream.bounds.split_instances);
        let split = motu_render::package_stream_split(pkg, &self.base, cap)?;
        let b = match split {
            Some(split) => {
                let split: &'p motu_render::StreamSplit = Box::leak(Box::new(split));
                split.view(&self.base)
            }
            None => self.base,
        };
        self.split_base = Some(b);
        Ok(b)
    }

    /// `base` with only the elements on. A subset's root copy is leaked: the streaming
    /// renderer borrows its view for its whole life, and each toggle leaks one root table
    /// (bounded by the user's key presses).
    fn view_for(
        &self,
        base: HierarchyView<'p>,
        on: &[bool],
    ) -> Result<HierarchyView<'p>, SourceError> {
        if on.iter().all(|e| *e) {
            return Ok(base);
        }
        let keep: Vec<u32> = self
            .element_ids
            .iter()
            .zip(on)
            .filter(|(_, on)| **on)
            .map(|(id, _)| *id)
            .collect();
        let subset = RootSubset::new(&base, |e| keep.contains(&e)).map_err(SourceError::Subset)?;
        let subset: &'p RootSubset = Box::leak(Box::new(subset));
        Ok(subset.view(&base))
    }

    /// Builds the structures for the elements `on` and the LOD mode asked for, for frames of
    /// `size` pixels (a streaming budget's test of the full build counts the frame's buffers).
    fn rebuild(
        &mut self,
        on: &[bool],
        lod_instance: bool,
        lod: &LodParams,
        size: (u32, u32),
    ) -> Result<(), SourceError> {
        // The previous streamer's structure cache stays warm for the next one.
        let old_cache = match &mut self.renderer {
            Renderer::Stream(Some(old)) => old.take_cache(),
            _ => None,
        };
        // Free the old structures before building the new ones (the budget holds one set).
        self.renderer = Renderer::Full(None);
        self.stream_fit = None;
        let mode = if lod_instance {
            LodMode::Instance
        } else {
            LodMode::Traversal
        };
        let settings = self.settings.clone();
        let s = &settings;
        let budget = s.vram_budget_bytes.unwrap_or(u64::MAX);
        if s.stream.as_ref().is_some_and(|st| !st.always) {
            // A budget that holds the whole scene draws the full build (never slower), with
            // LOD resolved as the streamer would (the same image).
            let view = self.view_for(self.base, on)?;
            let (fit, renderer) =
                fit::full_build_if_it_fits(&self.ctx, &view, self.meshes, s, size)?;
            self.stream_fit = Some(fit);
            if let Some(r) = renderer {
                self.lod_mode = choose_lod_mode(&view, lod, mode, true)?.mode;
                self.renderer = Renderer::Full(Some(r));
                self.built_for = on.to_vec();
                self.built_lod = Some((lod_instance, *lod));
                return Ok(());
            }
        }
        let view = match &s.stream {
            Some(stream) => {
                let base = self.split_base(stream)?;
                self.view_for(base, on)?
            }
            None => self.view_for(self.base, on)?,
        };
        let lod_choice = choose_lod_mode(&view, lod, mode, s.stream.is_some())?;
        self.lod_mode = lod_choice.mode;
        self.renderer = match &s.stream {
            None => {
                // Instance-level LOD: the rewritten hierarchy is built and a per-frame pass picks
                // each LOD instance's level (as `motu render` does).
                let scene = motu_render::build_scene(
                    &self.ctx,
                    &view,
                    self.meshes,
                    s.vram_budget_bytes,
                    s.max_allocations,
                    motu_gpu::BlasBuild::FastTrace,
                    lod_choice.instance.as_ref(),
                )?;
                Renderer::Full(Some(Box::new(motu_gpu::LiveRenderer::new(scene))))
            }
            Some(stream) => {
                let opts = stream.options(budget, s.max_allocations);
                let mut cache = old_cache.or_else(|| stream.cache.open(self.meshes.0));
                // The package's stored clusters (for the whole scene's view; an element
                // subset's are made), else the structure cache's, else made.
                let plan = motu_gpu::StreamPlan::load(
                    &view,
                    self.meshes.stored_proxy_clusters(),
                    cache.as_mut(),
                );
                let sr = motu_gpu::StreamingRenderer::with_plan_and_cache(
                    &self.ctx,
                    view,
                    plan,
                    self.meshes,
                    &opts,
                    cache,
                )
                .map_err(SourceError::StreamSetup)?;
                Renderer::Stream(Some(Box::new(sr)))
            }
        };
        self.built_for = on.to_vec();
        self.built_lod = Some((lod_instance, *lod));
        Ok(())
    }

    /// Whether the structures must be rebuilt for `lod_instance` with `lod`: only when the mode
    /// that would run changes (instance LOD applies to camera-only rules).
    fn lod_changed(&self, lod_instance: bool, lod: &LodParams) -> bool {
        let effective =
            |inst: bool, l: &LodParams| inst && motu_abi::lod_instance::rule_is_camera_only(l);
        match &self.built_lod {
            None => true,
            Some((inst, l)) => effective(*inst, l) != effective(lod_instance, lod),
        }
    }

    fn render_inner(
        &mut self,
        camera: &CameraParams,
        opts: &motu_gpu::RenderOptions,
        on: &[bool],
        lod_instance: bool,
    ) -> Result<SourceFrame, SourceError> {
        if on != self.built_for.as_slice()
            || self.lod_changed(lod_instance, &opts.lod)
            || self.stream_fit.as_ref().is_some_and(|f| f.outgrown(camera))
        {
            self.rebuild(on, lod_instance, &opts.lod, (camera.width, camera.height))?;
        }
        let stream_fit = self.stream_fit.as_ref().map(|f| f.stats.clone());
        let lod_mode = self.lod_mode;
        let total = self.total_structures;
        let progressive = self
            .settings
            .stream
            .as_ref()
            .is_some_and(ViewStreamSettings::progressive);
        match &mut self.renderer {
            Renderer::Full(Some(r)) => {
                let out = r.render_frame(camera, opts).map_err(SourceError::Gpu)?;
                let rep = r.scene().report();
                let alloc = r.scene().alloc_report();
                let stats = SourceStats {
                    vram_used_bytes: alloc.budget_block_bytes,
                    vram_budget_bytes: alloc.budget_bytes,
                    resident_structures: u64::from(rep.blas_count) + u64::from(rep.tlas_count),
                    total_structures: total,
                    passes: 1,
                    streaming: None,
                    incomplete_pixels: 0,
                    tlas_pieces_stale: 0,
                    lod_mode,
                    stream_fit,
                };
                let detail = Some(ViewDetail::Resources(Box::new(rep.into())));
                Ok(SourceFrame {
                    output: out,
                    stats,
                    detail,
                })
            }
            Renderer::Stream(Some(sr)) => {
                // A moving camera is probed where it is heading (one more step alike); one at
                // rest names itself, so a frame that left resident all it saw skips the probe
                // and one that did not prefetches what this camera needs.
                sr.set_next_camera(self.prev_camera.map(|p| camera.extrapolated_from(&p)));
                self.prev_camera = Some(*camera);
                let (out, st) = if progressive {
                    // Trace with what is resident, build toward the next frame (bounded).
                    sr.render_progressive(camera, opts)
                } else {
                    sr.render_frame(camera, opts)
                }
                .map_err(SourceError::StreamFrame)?;
                let alloc = sr.alloc_report();
                let stats = SourceStats {
                    vram_used_bytes: alloc.budget_block_bytes,
                    vram_budget_bytes: alloc.budget_bytes,
                    resident_structures: u64::from(st.resident_blases)
                        + u64::from(st.resident_tlases),
                    total_structures: total,
                    passes: st.passes,
                    streaming: Some((st.blas_built + st.tlas_built, st.evicted)),
                    incomplete_pixels: if st.complete {
                        0
                    } else {
                        st.incomplete_pixels.max(1)
                    },
                    tlas_pieces_stale: st.tlas_pieces_stale,
                    lod_mode,
                    stream_fit,
                };
                let detail = Some(ViewDetail::Stream(Box::new((&st).into())));
                Ok(SourceFrame {
                    output: out,
                    stats,
                    detail,
                })
            }
            _ => Err(SourceError::NoRenderer),
        }
    }
}

impl Drop for PackageSource<'_> {
    /// A streamed viewer keeping host clones wrote nothing to the cache directory while it
    /// ran (`motu_gpu` `clones.rs`): its structures go there at exit, for the next process.
    fn drop(&mut self) {
        if let Renderer::Stream(Some(sr)) = &mut self.renderer {
            if let Err(e) = sr.persist_cache() {
                tracing::warn!(error = %e, "structure cache: writing the viewer's structures failed");
            }
        }
    }
}

impl FrameSource for PackageSource<'_> {
    fn context(&self) -> &motu_gpu::Context {
        &self.ctx
    }

    fn render(
        &mut self,
        camera: &CameraParams,
        opts: &motu_gpu::RenderOptions,
        on: &[bool],
        lod_instance: bool,
    ) -> Result<SourceFrame, String> {
        self.render_inner(camera, opts, on, lod_instance)
            .map_err(|e| chain(&e))
    }

    fn base_colour(&self, mesh: u32) -> [f32; 3] {
        self.base_colours.get(&mesh).copied().unwrap_or([0.5; 3])
    }

    fn textured(&self) -> bool {
        self.textured
    }
}

#[cfg(test)]
mod tests;
