//! `motu view`: the interactive viewer (crates/motu-view) over a package: a full GPU build, or
//! the streaming renderer under `--vram-budget`/`--stream`.

use crate::cli::{BackendArg, LodModeArg, ViewArg, ViewArgs};
use crate::cmd::render::{camera_pose, choose_lod_mode, load_camera_path, PackageMeshes};
use crate::pipeline;
use anyhow::{bail, Context as _};
use glam::Vec3;
use motu_abi::camera::{CameraParams, CameraPose, RecordedPath};
use motu_abi::lod::LodParams;
use motu_abi::{HierarchyView, RootSubset};
use motu_pack::ScenePackage;
use motu_view::{FrameSource, SourceFrame, SourceStats, ViewOptions};
use serde_json::json;

/// Milliseconds of building per frame while flying when no build budget is given (at least
/// one structure is built per frame).
const INTERACTIVE_BUILD_MS: f64 = 30.0;

enum Renderer<'p> {
    Full(Option<Box<motu_gpu::LiveRenderer>>),
    Stream(Option<Box<motu_gpu::StreamingRenderer<'p>>>),
}

struct PackageSource<'p> {
    ctx: motu_gpu::Context,
    base: HierarchyView<'p>,
    meshes: &'p PackageMeshes<'p>,
    element_ids: Vec<u32>,
    /// The element set the renderer was built for.
    built_for: Vec<bool>,
    /// The LOD mode asked for when the renderer was built (instance where the rule allows it)
    /// with the LOD parameters it was decided for, and the mode that ran.
    built_lod: Option<(bool, LodParams)>,
    lod_mode: &'static str,
    renderer: Renderer<'p>,
    a: &'p ViewArgs,
    total_structures: u64,
}

impl<'p> PackageSource<'p> {
    /// The view with only the elements on. A subset's root copy is leaked: the streaming
    /// renderer borrows its view for its whole life, and each toggle leaks one root table
    /// (bounded by the user's key presses).
    fn view_for(&self, on: &[bool]) -> anyhow::Result<HierarchyView<'p>> {
        if on.iter().all(|e| *e) {
            return Ok(self.base);
        }
        let keep: Vec<u32> = self
            .element_ids
            .iter()
            .zip(on)
            .filter(|(_, on)| **on)
            .map(|(id, _)| *id)
            .collect();
        let subset = RootSubset::new(&self.base, |e| keep.contains(&e))
            .context("filtering the root for the element set")?;
        let subset: &'p RootSubset = Box::leak(Box::new(subset));
        Ok(subset.view(&self.base))
    }

    fn rebuild(&mut self, on: &[bool], lod_instance: bool, lod: &LodParams) -> anyhow::Result<()> {
        // Free the old structures before building the new ones (the budget holds one set).
        match &mut self.renderer {
            Renderer::Full(r) => *r = None,
            Renderer::Stream(r) => *r = None,
        }
        let view = self.view_for(on)?;
        let a = self.a;
        let budget = a.vram_budget.unwrap_or(u64::MAX);
        let streaming = matches!(self.renderer, Renderer::Stream(_));
        let mode = if lod_instance {
            LodModeArg::Instance
        } else {
            LodModeArg::Traversal
        };
        let lod_choice =
            choose_lod_mode(&view, lod, crate::cmd::render::lod_mode(mode), streaming)?;
        self.lod_mode = lod_choice.mode;
        match &mut self.renderer {
            Renderer::Full(r) => {
                // Instance-level LOD: the rewritten hierarchy is built and a per-frame pass picks
                // each LOD instance's level (as `motu render` does).
                let scene = motu_render::build_scene(
                    &self.ctx,
                    &view,
                    self.meshes,
                    a.vram_budget,
                    a.max_allocations,
                    lod_choice.instance.as_ref(),
                )?;
                *r = Some(Box::new(motu_gpu::LiveRenderer::new(scene)));
            }
            Renderer::Stream(r) => {
                let opts = motu_gpu::StreamOptions {
                    budget_bytes: budget,
                    // Interactive: bounded build work per frame keeps the window responsive;
                    // the next frames go on refining (what was built stays resident).
                    max_passes: a
                        .stream_passes
                        .unwrap_or(motu_gpu::StreamOptions::default().max_passes),
                    max_allocations: a
                        .max_allocations
                        .unwrap_or(motu_gpu::StreamOptions::default().max_allocations),
                    ..crate::cmd::render::stream_bounds(&a.stream_bounds).options()
                };
                let opts = motu_gpu::StreamOptions {
                    // Flying with no build budget given: one frame's worth of building per
                    // frame, so the window stays responsive while structures arrive.
                    frame_build_ms: if progressive(a)
                        && a.stream_bounds.stream_build_budget.is_none()
                        && a.stream_bounds.stream_build_ms.is_none()
                    {
                        INTERACTIVE_BUILD_MS
                    } else {
                        opts.frame_build_ms
                    },
                    ..opts
                };
                let sr = motu_gpu::StreamingRenderer::new(&self.ctx, view, self.meshes, &opts)
                    .context("setting up streaming (the resident skeleton must fit the budget)")?;
                *r = Some(Box::new(sr));
            }
        }
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
    ) -> anyhow::Result<SourceFrame> {
        if on != self.built_for.as_slice() || self.lod_changed(lod_instance, &opts.lod) {
            self.rebuild(on, lod_instance, &opts.lod)?;
        }
        let lod_mode = self.lod_mode;
        let total = self.total_structures;
        match &mut self.renderer {
            Renderer::Full(Some(r)) => {
                let out = r
                    .render_frame(camera, opts)
                    .context("rendering on the GPU")?;
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
                    lod_mode,
                };
                let detail = serde_json::to_string(rep).ok();
                Ok(SourceFrame {
                    output: out,
                    stats,
                    detail,
                })
            }
            Renderer::Stream(Some(sr)) => {
                let (out, st) = if progressive(self.a) {
                    // Trace with what is resident, build toward the next frame (bounded).
                    sr.render_progressive(camera, opts)
                } else {
                    sr.render_frame(camera, opts)
                }
                .context("streaming a frame")?;
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
                    lod_mode,
                };
                let detail = serde_json::to_string(&st).ok();
                Ok(SourceFrame {
                    output: out,
                    stats,
                    detail,
                })
            }
            _ => bail!("no renderer (an earlier rebuild failed)"),
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
            .map_err(|e| {
                let mut msg = e.to_string();
                for c in e.chain().skip(1) {
                    msg.push_str(&format!(": {c}"));
                }
                msg
            })
    }
}

/// Whether streaming frames are progressive (one trace with what is resident, then a build
/// bounded by the frame budget for the next frame): `--stream-passes 1`, or flying without
/// `--stream-passes`.
fn progressive(a: &ViewArgs) -> bool {
    a.stream_passes == Some(1) || (a.frames.is_none() && a.stream_passes.is_none())
}

/// Writes `bytes` to `path` atomically (temp file, fsync, rename).
fn write_atomic(path: &std::path::Path, bytes: &[u8]) -> anyhow::Result<()> {
    use std::io::Write;
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(std::path::Path::new("."));
    let tmp = dir.join(format!(
        ".{}.tmp{}",
        path.file_name().and_then(|n| n.to_str()).unwrap_or("out"),
        std::process::id()
    ));
    let mut f = std::fs::File::create(&tmp)?;
    f.write_all(bytes)?;
    f.sync_all()?;
    drop(f);
    std::fs::rename(&tmp, path)?;
    Ok(())
}

pub fn run(a: ViewArgs) -> anyhow::Result<()> {
    // Before any work: without a display the answer is `motu render`.
    motu_view::check_display()?;
    if a.stream_passes == Some(0) {
        bail!("--stream-passes must be at least 1 (1: trace with what is resident, then build for the next frame)");
    }
    let streaming = a.stream || a.vram_budget.is_some();
    if !streaming && crate::cmd::render::stream_bounds(&a.stream_bounds).given() {
        bail!(
            "--stream-fallback, --stream-build-budget and --stream-build-ms bound streaming \
             frames: add --stream or --vram-budget"
        );
    }
    if a.frames == Some(0) {
        bail!("--frames must be at least 1");
    }
    if a.frames.is_none() && (a.screenshot.is_some() || a.aov.is_some() || a.stats.is_some()) {
        bail!("--screenshot, --aov and --stats need --frames N (render N frames, write the last, exit)");
    }
    let pkg: ScenePackage = pipeline::open(&a.package)?;
    let base = pkg.view()?;
    let meta = pkg.meta();
    let names: Vec<String> = meta.elements.iter().map(|e| e.name.clone()).collect();
    let element_ids: Vec<u32> = meta.elements.iter().map(|e| e.id).collect();
    if !a.subset.is_empty() {
        pipeline::resolve_subset(&a.subset, &names)?;
    }
    let elements_on: Vec<bool> = names
        .iter()
        .map(|n| a.subset.is_empty() || a.subset.contains(n))
        .collect();
    let replay = match &a.camera_path {
        Some(p) => Some(load_camera_path(p)?),
        None => None,
    };
    let (start, cw, ch) = camera_pose(&pkg, &base, a.camera.as_deref(), a.width, a.height)?;
    let (width, height) = match &replay {
        Some(RecordedPath {
            width: Some(w),
            height: Some(h),
            ..
        }) if a.width.is_none() && a.height.is_none() => (*w, *h),
        _ => (cw, ch),
    };
    let cameras: Vec<(String, CameraPose)> = meta
        .cameras
        .iter()
        .map(|c| -> anyhow::Result<(String, CameraPose)> {
            let (p, _, _) = camera_pose(&pkg, &base, Some(&c.name), Some(1), Some(1))?;
            Ok((c.name.clone(), p))
        })
        .collect::<anyhow::Result<_>>()?;
    let root = &base.tlases[base.root_tlas as usize];
    let radius = ((Vec3::from_array(root.bounds_max) - Vec3::from_array(root.bounds_min)).length()
        * 0.5)
        .max(1e-3);
    let backend = match a.backend {
        Some(BackendArg::Cpu) => bail!(
            "`motu view` renders on the GPU (pipeline or query); the CPU backend is `motu render --backend cpu`"
        ),
        Some(BackendArg::Query) => motu_gpu::Backend::Query,
        Some(BackendArg::Pipeline) => motu_gpu::Backend::Pipeline,
        None => {
            let devices = motu_gpu::list_devices().context("listing Vulkan devices")?;
            let ds = match a.device {
                Some(i) => devices.get(i..i + 1).unwrap_or(&[]),
                None => &devices[..],
            };
            match crate::cmd::render::best_backend(ds) {
                BackendArg::Query => motu_gpu::Backend::Query,
                BackendArg::Pipeline => motu_gpu::Backend::Pipeline,
                BackendArg::Cpu => bail!(
                    "no Vulkan device with ray tracing (`motu devices` lists them); `motu render --backend cpu` renders without one"
                ),
            }
        }
    };
    let render = motu_gpu::RenderOptions {
        backend,
        view: match a.view {
            ViewArg::Shaded => motu_gpu::View::Shaded,
            ViewArg::Ids => motu_gpu::View::Ids,
            ViewArg::Lod => motu_gpu::View::Lod,
            ViewArg::Heatmap => motu_gpu::View::Heatmap,
        },
        lod: LodParams {
            forced_lod: a
                .lod
                .map(|l| l as i32)
                .unwrap_or(motu_abi::lod::LOD_NOT_FORCED),
            r_max_px: a.lod_r_max,
            stochastic: u32::from(a.lod_stochastic),
            ..LodParams::default()
        },
        stack_size: a.stack_size,
        frames: 1,
        // The scene's lights with `motu render`'s defaults (one AO ray, one sample, exposure
        // 0), so a view frame equals a render of the same camera.
        shading: motu_render::scene_shading(Default::default(), &pkg, &base),
        ..Default::default()
    };
    if !(a.lod_r_max.is_finite() && a.lod_r_max > 0.0) {
        bail!("--lod-r-max must be a positive number of pixels");
    }
    let frames = a.frames.or(replay.as_ref().map(|p| p.poses.len() as u32));
    let replay_poses = replay.as_ref().map(|p| {
        let n = frames.unwrap_or(p.poses.len() as u32);
        (0..n).map(|f| p.sample(f, n)).collect::<Vec<_>>()
    });
    let opts = ViewOptions {
        title: format!("motu view — {}", a.package.display()),
        width,
        height,
        start,
        cameras,
        render,
        lod_instance: a.lod_mode == LodModeArg::Instance,
        elements: names,
        elements_on: elements_on.clone(),
        speed: a.speed.unwrap_or(radius * 0.25),
        frames,
        replay: replay_poses,
        overlay: a.overlay || a.frames.is_none(),
        vsync: !a.no_vsync,
        display: None,
    };
    let meshes = PackageMeshes(&pkg);
    let total_structures = (base.blases.len() + base.tlases.len()) as u64;
    let result = motu_view::run(opts, |o| {
        let ctx = motu_gpu::Context::new(&motu_gpu::ContextOptions {
            device_index: a.device,
            limit_overrides: motu_gpu::LimitOverrides {
                max_memory_allocation_count: a.max_allocations,
                ..Default::default()
            },
            require: match backend {
                motu_gpu::Backend::Query => motu_gpu::Requirement::RayQuery,
                motu_gpu::Backend::Pipeline => motu_gpu::Requirement::RayPipeline,
            },
            presentation: o.display,
            ..Default::default()
        })
        .map_err(|e| format!("opening a Vulkan device that can present: {e}"))?;
        let mut src = PackageSource {
            ctx,
            base,
            meshes: &meshes,
            element_ids: element_ids.clone(),
            built_for: Vec::new(),
            built_lod: None,
            lod_mode: "",
            renderer: if streaming {
                Renderer::Stream(None)
            } else {
                Renderer::Full(None)
            },
            a: &a,
            total_structures,
        };
        src.rebuild(&elements_on, o.lod_instance, &o.render.lod)
            .map_err(|e| format!("{e:#}"))?;
        Ok(src)
    })
    .context("motu view")?;
    if let Some(p) = &a.record {
        let path = RecordedPath {
            poses: result.poses.clone(),
            width: Some(result.last_size[0]),
            height: Some(result.last_size[1]),
        };
        write_atomic(p, path.to_json().as_bytes())
            .with_context(|| format!("writing {}", p.display()))?;
        eprintln!("recorded {} frames to {}", result.poses.len(), p.display());
    }
    if a.frames.is_none() {
        return Ok(());
    }
    let [w, h] = result.last_size;
    let last = result.last.as_ref().context("no frame was shown")?;
    if let Some(p) = &a.screenshot {
        let px = result.screenshot_rgba8.as_ref().context(
            "the swapchain image could not be read back (the surface does not allow TRANSFER_SRC)",
        )?;
        motu_trace::write_png(p, w, h, px).with_context(|| format!("writing {}", p.display()))?;
    }
    if let Some(p) = &a.aov {
        last.output
            .aov
            .save(p)
            .with_context(|| format!("writing {}", p.display()))?;
    }
    if let Some(p) = &a.stats {
        let mut stats = serde_json::to_value(&last.output.stats)?;
        let mut ms = result.frame_ms.clone();
        ms.sort_by(f64::total_cmp);
        stats["frames"] = json!(result.frames_shown);
        stats["wall_ms_per_frame_median"] = json!(ms.get(ms.len() / 2).copied().unwrap_or(0.0));
        stats["wall_ms_per_frame"] = json!(result.frame_ms);
        stats["window"] = json!({"width": w, "height": h, "presented_via": "swapchain"});
        stats["vram_used_bytes"] = json!(last.stats.vram_used_bytes);
        stats["resident_structures"] = json!(last.stats.resident_structures);
        stats["total_structures"] = json!(last.stats.total_structures);
        stats["streaming"] = json!(last.stats.streaming.is_some());
        stats["incomplete_frames"] = json!(result.incomplete_frames);
        stats["incomplete_pixels_per_frame"] = json!(result.incomplete_pixels_per_frame);
        stats["lod_mode"] = json!(last.stats.lod_mode);
        if let Some(d) = &last.detail {
            stats["detail"] = serde_json::from_str(d).unwrap_or(json!(null));
        }
        stats["package"] = json!(a.package.display().to_string());
        write_atomic(p, serde_json::to_string_pretty(&stats)?.as_bytes())
            .with_context(|| format!("writing {}", p.display()))?;
    }
    eprintln!(
        "view: {} frames shown ({}×{}, {}), last {:.2} Mrays/s, {:.2} traces/ray",
        result.frames_shown,
        w,
        h,
        last.output.stats.backend,
        last.output.stats.rays_per_second / 1e6,
        last.output.stats.traces_per_ray
    );
    Ok(())
}
