//! `motu render` and `motu compare`.

use crate::cli::{BackendArg, CompareArgs, RenderArgs, ViewArg};
use crate::pipeline;
use anyhow::{bail, Context};
use glam::Vec3;
use motu_abi::aov::Aov;
use motu_abi::camera::{camera_path, CameraParams, CameraPath, CameraPose};
use motu_abi::lod::LodParams;
use motu_abi::{HierarchyView, RootSubset};
use motu_pack::ScenePackage;
use serde_json::{json, Value};

/// Mesh data for the tracers, straight from the package's chunks.
pub struct PackageMeshes<'a>(pub &'a ScenePackage);

impl motu_trace::MeshSource for PackageMeshes<'_> {
    fn load(&self, mesh_record: u32) -> Result<motu_trace::MeshGeometry, String> {
        let g = self
            .0
            .mesh_geometry(mesh_record)
            .map_err(|e| e.to_string())?;
        Ok(motu_trace::MeshGeometry {
            positions: g.positions,
            indices: g.indices,
            normals: g.normals,
            uvs: g.uvs,
        })
    }
}

/// The camera to render: by name, else the scene's active camera, else a view of the bounds.
pub fn camera_params(
    pkg: &ScenePackage,
    view: &HierarchyView<'_>,
    name: Option<&str>,
    width: Option<u32>,
    height: Option<u32>,
) -> anyhow::Result<CameraParams> {
    let (pose, w, h) = camera_pose(pkg, view, name, width, height)?;
    Ok(pose.params(w, h))
}

/// The camera as a pose (for camera paths) and the image size.
pub fn camera_pose(
    pkg: &ScenePackage,
    view: &HierarchyView<'_>,
    name: Option<&str>,
    width: Option<u32>,
    height: Option<u32>,
) -> anyhow::Result<(CameraPose, u32, u32)> {
    let meta = pkg.meta();
    let cam = match name {
        Some(n) => Some(meta.cameras.iter().find(|c| c.name == n).with_context(|| {
            let names: Vec<&str> = meta.cameras.iter().map(|c| c.name.as_str()).collect();
            format!(
                "no camera named '{n}': the scene has {}",
                if names.is_empty() {
                    "none".to_string()
                } else {
                    names.join(", ")
                }
            )
        })?),
        None => meta.cameras.first(),
    };
    let (eye, fwd, up, fov, mirror, cw, ch) = match cam {
        Some(c) => (
            Vec3::from_array(c.world_eye),
            Vec3::from_array(c.world_forward),
            Vec3::from_array(c.world_up),
            c.fov_deg,
            c.mirror_x,
            c.width,
            c.height,
        ),
        None => {
            // No camera in the scene: look at the root's bounds from the front.
            let r = &view.tlases[view.root_tlas as usize];
            let (lo, hi) = (
                Vec3::from_array(r.bounds_min),
                Vec3::from_array(r.bounds_max),
            );
            let c = (lo + hi) * 0.5;
            let radius = ((hi - lo).length() * 0.5).max(1e-3);
            let eye = c + Vec3::new(0.3, 0.4, 1.0).normalize() * radius * 2.2;
            (eye, (c - eye).normalize(), Vec3::Y, 50.0, false, 640, 480)
        }
    };
    let aspect = cw.max(1) as f64 / ch.max(1) as f64;
    let (w, h) = match (width, height) {
        (Some(w), Some(h)) => (w, h),
        (Some(w), None) => (w, ((w as f64 / aspect).round() as u32).max(1)),
        (None, Some(h)) => (((h as f64 * aspect).round() as u32).max(1), h),
        (None, None) => (cw, ch),
    };
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        bail!("image size {w}×{h} is out of range (1–16384 per side)");
    }
    let pose = CameraPose {
        world_eye: eye,
        world_forward: fwd,
        world_up: up,
        fov_deg: fov,
        mirror_x: mirror,
    };
    Ok((pose, w, h))
}

impl motu_gpu::MeshBlobSource for PackageMeshes<'_> {
    fn mesh_data(
        &self,
        mesh_record: u32,
    ) -> Result<
        (
            std::borrow::Cow<'_, [[f32; 3]]>,
            std::borrow::Cow<'_, [u32]>,
        ),
        String,
    > {
        self.0.mesh_slices(mesh_record).map_err(|e| e.to_string())
    }

    fn mesh_shading(
        &self,
        mesh_record: u32,
    ) -> Result<
        (
            Option<std::borrow::Cow<'_, [[f32; 3]]>>,
            Option<std::borrow::Cow<'_, [[f32; 2]]>>,
        ),
        String,
    > {
        self.0
            .mesh_shading_slices(mesh_record)
            .map_err(|e| e.to_string())
    }
}

/// How the shaded view is lit: the scene's lights (the brightest `MAX_LIGHTS`; infinite
/// lights become the sky colour), ambient occlusion reaching a fifth of the scene's diagonal,
/// and the sampling and exposure options. A scene without lights gets the renderers' key
/// light and sky.
pub fn scene_shading(
    a: &RenderArgs,
    pkg: &ScenePackage,
    view: &HierarchyView<'_>,
) -> motu_abi::shade::Shading {
    use motu_abi::shade::{
        Shading, LIGHT_AREA, LIGHT_DISTANT, LIGHT_POINT, LIGHT_SPOT, MAX_LIGHTS,
    };
    use motu_scene::LightKind;
    let mut sh = Shading {
        ao_samples: a.ao_samples,
        spp: a.spp.max(1),
        exposure_ev: a.exposure,
        ..Default::default()
    };
    if let Some(root) = view.tlases.get(view.root_tlas as usize) {
        let d = Vec3::from_array(root.bounds_max) - Vec3::from_array(root.bounds_min);
        if d.is_finite() && d.length() > 0.0 {
            sh.ao_distance = 0.2 * d.length();
        }
    }
    let mut lights = Vec::new();
    let mut sky: Option<[f32; 3]> = None;
    let mut skipped = 0usize;
    for l in &pkg.meta().lights {
        let radiance = l.color.map(|c| c * l.intensity);
        let rec = motu_abi::LightRecord {
            world_position: l.world_position,
            world_direction: Vec3::from_array(l.world_direction)
                .normalize_or(Vec3::NEG_Y)
                .to_array(),
            radiance,
            ..Default::default()
        };
        let rec = match l.kind {
            LightKind::Distant => motu_abi::LightRecord {
                kind: LIGHT_DISTANT,
                ..rec
            },
            LightKind::Point => motu_abi::LightRecord {
                kind: LIGHT_POINT,
                ..rec
            },
            LightKind::Spot => {
                let [cone, delta] = l.cone_deg.unwrap_or([30.0, 5.0]);
                motu_abi::LightRecord {
                    kind: LIGHT_SPOT,
                    cos_total: cone.to_radians().cos(),
                    cos_falloff: (cone - delta).max(0.0).to_radians().cos(),
                    ..rec
                }
            }
            LightKind::Area => motu_abi::LightRecord {
                kind: LIGHT_AREA,
                cos_total: l.radius,
                ..rec
            },
            LightKind::Infinite => {
                let s = sky.get_or_insert([0.0; 3]);
                for (s, r) in s.iter_mut().zip(radiance) {
                    *s += r;
                }
                continue;
            }
            LightKind::Other => {
                skipped += 1;
                continue;
            }
        };
        lights.push(rec);
    }
    if skipped > 0 {
        eprintln!("warning: {skipped} light(s) of a kind motu does not shade (goniometric, projection, ...) left out");
    }
    if lights.len() > MAX_LIGHTS {
        let peak = |r: &motu_abi::LightRecord| r.radiance.iter().cloned().fold(0.0f32, f32::max);
        lights.sort_by(|x, y| peak(y).total_cmp(&peak(x)));
        eprintln!(
            "warning: the scene has {} lights; shading with the {MAX_LIGHTS} brightest",
            lights.len()
        );
        lights.truncate(MAX_LIGHTS);
    }
    if lights.is_empty() && sky.is_some() {
        // Sky light only: no key light (the sky term lights the scene).
        lights.push(motu_abi::LightRecord {
            kind: LIGHT_DISTANT,
            world_direction: [0.0, -1.0, 0.0],
            radiance: [0.0; 3],
            ..Default::default()
        });
    }
    for (i, l) in lights.iter().enumerate() {
        sh.lights[i] = *l;
    }
    sh.light_count = lights.len() as u32;
    sh.sky = sky;
    sh
}

fn gpu_context(a: &RenderArgs, backend: BackendArg) -> anyhow::Result<motu_gpu::Context> {
    use motu_gpu::{ContextOptions, LimitOverrides, Requirement};
    motu_gpu::Context::new(&ContextOptions {
        device_index: a.device,
        limit_overrides: LimitOverrides {
            max_memory_allocation_count: a.max_allocations,
            ..Default::default()
        },
        require: match backend {
            BackendArg::Query => Requirement::RayQuery,
            _ => Requirement::RayPipeline,
        },
        ..Default::default()
    })
    .context("opening a Vulkan device for ray tracing (`motu devices` lists them; `--backend cpu` needs none)")
}

fn gpu_render_options(
    a: &RenderArgs,
    lod: LodParams,
    backend: BackendArg,
    frames: u32,
    shading: motu_abi::shade::Shading,
) -> motu_gpu::RenderOptions {
    motu_gpu::RenderOptions {
        backend: match backend {
            BackendArg::Query => motu_gpu::Backend::Query,
            _ => motu_gpu::Backend::Pipeline,
        },
        view: match a.view {
            ViewArg::Shaded => motu_gpu::View::Shaded,
            ViewArg::Ids => motu_gpu::View::Ids,
            ViewArg::Lod => motu_gpu::View::Lod,
            ViewArg::Heatmap => motu_gpu::View::Heatmap,
        },
        lod,
        stack_size: a.stack_size,
        frames,
        shading,
        ..Default::default()
    }
}

/// `--stream`: builds only what rays touch, evicting under the budget, frame by frame along a
/// camera path (`--frames N`; one frame renders the camera itself).
fn render_streaming(
    a: &RenderArgs,
    pkg: &ScenePackage,
    view: &HierarchyView<'_>,
    lod: LodParams,
    backend: BackendArg,
) -> anyhow::Result<(Aov, Vec<u8>, Value)> {
    let ctx = gpu_context(a, backend)?;
    let (pose, w, h) = camera_pose(pkg, view, a.camera.as_deref(), a.width, a.height)?;
    let root = &view.tlases[view.root_tlas as usize];
    let centre = (Vec3::from_array(root.bounds_min) + Vec3::from_array(root.bounds_max)) * 0.5;
    let path = CameraPath::sweep_and_dolly((centre - pose.world_eye).length(), 0.3);
    let meshes = PackageMeshes(pkg);
    let opts = motu_gpu::StreamOptions {
        budget_bytes: a.vram_budget.unwrap_or(u64::MAX),
        max_allocations: a
            .max_allocations
            .unwrap_or(motu_gpu::StreamOptions::default().max_allocations),
        ..Default::default()
    };
    let mut sr = motu_gpu::StreamingRenderer::new(&ctx, *view, &meshes, &opts)
        .context("setting up streaming (the resident skeleton must fit the budget)")?;
    let ropts = gpu_render_options(a, lod, backend, 1, scene_shading(a, pkg, view));
    if a.spp > 1 {
        eprintln!(
            "warning: --stream renders one sample per pixel (--spp {} ignored)",
            a.spp
        );
    }
    let mut frames = Vec::new();
    let mut last = None;
    for f in 0..a.frames {
        let cam = camera_path(&pose, &path, f, a.frames).params(w, h);
        let (out, st) = sr
            .render_frame(&cam, &ropts)
            .with_context(|| format!("streaming frame {f}"))?;
        eprintln!(
            "frame {f}: {} passes{}, {} BLAS + {} TLAS built, {} evicted, {} streamed, {:.1} ms building, VRAM {} of {}",
            st.passes,
            if st.complete { "" } else { " (incomplete: pass cap)" },
            st.blas_built,
            st.tlas_built,
            st.evicted,
            crate::size::format_size(st.bytes_streamed),
            st.build_ms,
            crate::size::format_size(st.vram_peak_bytes),
            crate::size::format_size(st.vram_budget_bytes),
        );
        frames.push(serde_json::to_value(&st)?);
        last = Some(out);
    }
    let out = last.context("no frame rendered")?;
    let mut stats = serde_json::to_value(&out.stats)?;
    let totals = sr.totals();
    let after_first: Vec<f64> = frames
        .iter()
        .skip(1)
        .filter_map(|f| f["passes"].as_f64())
        .collect();
    stats["stream"] = json!({
        "frames": frames,
        "totals": totals,
        "mean_passes_after_first": if after_first.is_empty() { Value::Null } else { json!(after_first.iter().sum::<f64>() / after_first.len() as f64) },
    });
    drop(sr);
    ctx.check_validation()
        .context("Vulkan validation reported errors")?;
    Ok((out.aov, out.rgba8, stats))
}

/// Builds the package's structures on the GPU under the budget and renders with a traversal
/// shader backend.
fn render_gpu(
    a: &RenderArgs,
    pkg: &ScenePackage,
    view: &HierarchyView<'_>,
    camera: &CameraParams,
    lod: LodParams,
    backend: BackendArg,
) -> anyhow::Result<(Aov, Vec<u8>, Value)> {
    let ctx = gpu_context(a, backend)?;
    let budget = a.vram_budget.unwrap_or(u64::MAX);
    let build = motu_gpu::BuildOptions {
        budget_bytes: budget,
        max_allocations: a
            .max_allocations
            .unwrap_or(motu_gpu::BuildOptions::default().max_allocations),
        // Each half of the staging ring should hold a build batch's geometry so uploads overlap
        // builds; host-visible memory counts against the budget on unified-memory devices.
        staging_bytes: (budget / 8).clamp(4 << 20, 64 << 20),
        ..Default::default()
    };
    let meshes = PackageMeshes(pkg);
    let scene = motu_gpu::GpuScene::build(&ctx, view, &meshes, &build)
        .context("building acceleration structures")?;
    let opts = gpu_render_options(a, lod, backend, a.frames, scene_shading(a, pkg, view));
    let out = motu_gpu::render(&ctx, &scene, camera, &opts).context("rendering on the GPU")?;
    let mut stats = serde_json::to_value(&out.stats)?;
    stats["resources"] = serde_json::to_value(scene.report())?;
    drop(scene);
    ctx.check_validation()
        .context("Vulkan validation reported errors")?;
    Ok((out.aov, out.rgba8, stats))
}

/// `query` where a device has ray queries (usually fastest on RTX), else `pipeline`, else the CPU.
pub fn best_backend(devices: &[motu_gpu::DeviceReport]) -> BackendArg {
    if devices.iter().any(|d| d.ray_query) {
        BackendArg::Query
    } else if devices.iter().any(|d| d.ray_pipeline) {
        BackendArg::Pipeline
    } else {
        BackendArg::Cpu
    }
}

fn view_name(v: ViewArg) -> &'static str {
    match v {
        ViewArg::Shaded => "shaded",
        ViewArg::Heatmap => "heatmap",
        ViewArg::Lod => "lod",
        ViewArg::Ids => "ids",
    }
}

/// Adds the contract's keys to a backend's stats object.
fn contract_stats(mut stats: Value, extra: Value) -> Value {
    if let (Some(s), Some(e)) = (stats.as_object_mut(), extra.as_object()) {
        for (k, v) in e {
            s.entry(k.clone()).or_insert(v.clone());
        }
    }
    stats
}

pub fn run(a: RenderArgs) -> anyhow::Result<()> {
    let pkg = pipeline::open(&a.package)?;
    let base = pkg.view()?;
    let names: Vec<String> = pkg.meta().elements.iter().map(|e| e.name.clone()).collect();
    let subset = if a.subset.is_empty() {
        None
    } else {
        pipeline::resolve_subset(&a.subset, &names)?;
        // Records hold the imported scene's element ids; `meta` maps names to them.
        let keep: Vec<u32> = pkg
            .meta()
            .elements
            .iter()
            .filter(|e| a.subset.contains(&e.name))
            .map(|e| e.id)
            .collect();
        Some(
            RootSubset::new(&base, |e| keep.contains(&e))
                .context("filtering the root for --subset")?,
        )
    };
    let view = match &subset {
        Some(s) => s.view(&base),
        None => base,
    };
    let camera = camera_params(&pkg, &view, a.camera.as_deref(), a.width, a.height)?;
    let lod = LodParams {
        forced_lod: a
            .lod
            .map(|l| l as i32)
            .unwrap_or(motu_abi::lod::LOD_NOT_FORCED),
        r_max_px: a.lod_r_max,
        shadow_bias: a.shadow_lod_bias,
        stochastic: u32::from(a.lod_stochastic),
    };
    let r_max_ok = a.lod_r_max.is_finite() && a.lod_r_max > 0.0;
    let bias_ok = a.shadow_lod_bias.is_finite() && a.shadow_lod_bias >= 0.0;
    if !r_max_ok || !bias_ok {
        bail!("--lod-r-max must be a positive number of pixels and --shadow-lod-bias ≥ 0");
    }
    let backend = match a.backend {
        Some(b) => b,
        None => match motu_gpu::list_devices() {
            Ok(devices) => match a.device {
                Some(i) => best_backend(devices.get(i..i + 1).unwrap_or(&[])),
                None => best_backend(&devices),
            },
            Err(e) => {
                eprintln!("warning: no Vulkan ray-tracing device ({e}); rendering on the CPU");
                BackendArg::Cpu
            }
        },
    };
    if backend == BackendArg::Cpu && a.backend.is_none() {
        eprintln!("warning: no device with ray tracing; rendering with the CPU reference backend");
    }
    if a.stream && backend == BackendArg::Cpu {
        bail!("--stream builds acceleration structures on a GPU: use --backend pipeline or query");
    }
    if a.frames == 0 {
        bail!("--frames must be at least 1");
    }
    if !a.exposure.is_finite() {
        bail!("--exposure must be a finite number of stops");
    }
    let (aov, rgba8, stats): (Aov, Vec<u8>, Value) = match backend {
        BackendArg::Cpu => {
            let meshes = PackageMeshes(&pkg);
            let tracer =
                motu_trace::Tracer::new(view, &meshes).context("preparing the CPU tracer")?;
            let opts = motu_trace::RenderOptions {
                view: view_name(a.view).parse().map_err(anyhow::Error::msg)?,
                lod,
                shading: scene_shading(&a, &pkg, &view),
                ..Default::default()
            };
            let mut out =
                motu_trace::render_with(&tracer, &camera, &opts).context("rendering on the CPU")?;
            let mut times = vec![out.stats.ms_per_frame];
            for _ in 1..a.frames {
                let o = motu_trace::render_with(
                    &tracer,
                    &camera,
                    &motu_trace::RenderOptions {
                        prepare: false,
                        ..opts
                    },
                )?;
                times.push(o.stats.ms_per_frame);
                out = o;
            }
            times.sort_by(f64::total_cmp);
            let median = times[times.len() / 2];
            let mut stats = serde_json::to_value(&out.stats)?;
            stats["ms_per_frame"] = json!(median);
            stats["frames"] = json!(a.frames);
            (out.aov, out.rgba8, stats)
        }
        BackendArg::Pipeline | BackendArg::Query if a.stream => {
            render_streaming(&a, &pkg, &view, lod, backend)?
        }
        BackendArg::Pipeline | BackendArg::Query => {
            render_gpu(&a, &pkg, &view, &camera, lod, backend)?
        }
    };
    let stats = contract_stats(
        stats,
        json!({
            "backend": match backend { BackendArg::Cpu => "cpu", BackendArg::Pipeline => "pipeline", BackendArg::Query => "query" },
            "view": view_name(a.view),
            "vram_budget_bytes": a.vram_budget.unwrap_or(0),
            "vram_peak_bytes": 0,
            "allocation_count": 0,
            "as_bytes": 0,
            "passes": 1,
            "subset": a.subset,
            "package": a.package.display().to_string(),
        }),
    );
    motu_trace::write_png(&a.output, camera.width, camera.height, &rgba8)
        .with_context(|| format!("writing {}", a.output.display()))?;
    if let Some(p) = &a.aov {
        aov.save(p)
            .with_context(|| format!("writing {}", p.display()))?;
    }
    if let Some(p) = &a.stats {
        std::fs::write(p, serde_json::to_string_pretty(&stats)?)
            .with_context(|| format!("writing {}", p.display()))?;
    }
    eprintln!(
        "rendered {} ({}×{}, {}): {:.1} ms/frame, {:.2} Mrays/s, {:.2} traces/ray",
        a.output.display(),
        camera.width,
        camera.height,
        stats["backend"].as_str().unwrap_or("?"),
        stats["ms_per_frame"].as_f64().unwrap_or(0.0),
        stats["rays_per_second"].as_f64().unwrap_or(0.0) / 1e6,
        stats["traces_per_ray"].as_f64().unwrap_or(0.0),
    );
    Ok(())
}

pub fn compare(a: CompareArgs) -> anyhow::Result<()> {
    let x = Aov::load(&a.a).with_context(|| format!("reading {}", a.a.display()))?;
    let y = Aov::load(&a.b).with_context(|| format!("reading {}", a.b.display()))?;
    let r = motu_trace::compare(&x, &y, a.depth_epsilon).context("comparing")?;
    if let Some(p) = &a.diff {
        motu_trace::write_png(p, x.width, x.height, &r.diff_rgba8)
            .with_context(|| format!("writing {}", p.display()))?;
    }
    let ok = r.fraction <= a.max_mismatch;
    if a.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&json!({
                "mismatched": r.mismatched, "total": r.total, "fraction": r.fraction,
                "bbox": r.bbox, "max_mismatch": a.max_mismatch, "pass": ok,
            }))?
        );
    } else {
        let bbox = r
            .bbox
            .map(|b| format!(" in [{}, {}]–[{}, {}]", b[0], b[1], b[2], b[3]))
            .unwrap_or_default();
        println!(
            "mismatch {:.6} ({} of {} pixels){bbox}",
            r.fraction, r.mismatched, r.total
        );
    }
    if !ok {
        bail!(
            "mismatch fraction {:.6} is above --max-mismatch {}",
            r.fraction,
            a.max_mismatch
        );
    }
    Ok(())
}
