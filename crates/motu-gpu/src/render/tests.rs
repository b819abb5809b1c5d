//! GPU tests of the scene build and both traversal backends against the CPU oracle
//! (motu-trace) on hand-built hierarchies. Small images: lavapipe runs them on 2 cores.

use std::borrow::Cow;

use glam_free::*;
use motu_abi::aov::MISS;
use motu_abi::camera::CameraParams;
use motu_abi::lod::LodParams;
use motu_trace::testutil::{srt, uv_sphere, HierarchyBuilder, OwnedHierarchy, PiTarget};

use crate::testutil::{assert_no_validation_errors, context_or_skip};
use crate::{
    render, Backend, BuildOptions, Context, ContextOptions, GpuError, GpuScene, LimitOverrides,
    MeshBlobSource, MeshSourceError, RenderOptions, Requirement, ValidationRequest, View,
};

/// glam is not a dependency of motu-gpu; the camera comes from motu-abi's constructor.
mod glam_free {
    pub fn camera(eye: [f32; 3], target: [f32; 3], size: u32) -> motu_abi::camera::CameraParams {
        let fwd = [target[0] - eye[0], target[1] - eye[1], target[2] - eye[2]];
        motu_abi::camera::CameraParams::new(
            eye.into(),
            fwd.into(),
            [0.0, 1.0, 0.0].into(),
            45.0,
            false,
            size,
            size,
        )
    }
}

/// Root TLAS: a ground-ish sphere (triangles) and a BLAS of PIs, each a rotated/scaled copy of
/// a leaf TLAS (two spheres) or a LOD selector over two sphere resolutions.
fn two_level() -> OwnedHierarchy {
    let mut b = HierarchyBuilder::new();
    let red = b.material([0.9, 0.2, 0.2]);
    let fine = b.mesh(0, 0, red, uv_sphere(12));
    let coarse = b.mesh(0, 1, red, uv_sphere(5));
    let big = b.mesh(1, 0, 0, uv_sphere(16));
    let fine_blas = b.triangle_blas(&[fine]);
    let coarse_blas = b.triangle_blas(&[coarse]);
    let big_blas = b.triangle_blas(&[big]);
    let leaf = b.tlas(&[
        (srt(0.5, 0.0, [-0.6, 0.0, 0.0]), fine_blas),
        (srt(0.4, 0.3, [0.6, 0.1, 0.0]), fine_blas),
    ]);
    let lod0 = b.tlas(&[(srt(1.0, 0.0, [0.0; 3]), fine_blas)]);
    let lod1 = b.tlas(&[(srt(1.0, 0.0, [0.0; 3]), coarse_blas)]);
    let sel = b.lod_selector(&[lod0, lod1], 0);
    let pis = b.pi_blas(&[
        (srt(1.0, 0.2, [-1.5, 0.5, 0.0]), PiTarget::Tlas(leaf)),
        (srt(0.8, -0.5, [1.2, -0.3, 0.5]), PiTarget::Tlas(leaf)),
        (srt(0.6, 0.0, [0.0, 1.2, -1.0]), PiTarget::LodSelector(sel)),
        (srt(0.3, 0.0, [0.3, -1.0, 1.0]), PiTarget::LodSelector(sel)),
    ]);
    let root = b.tlas(&[
        (srt(3.0, 0.0, [0.0, -4.2, -1.0]), big_blas),
        (srt(1.0, 0.1, [0.0, 0.0, 0.0]), pis),
    ]);
    b.finish(root)
}

/// [`two_level`] and its GPU scene.
fn two_level_scene(ctx: &Context) -> (OwnedHierarchy, GpuScene) {
    let h = two_level();
    let scene = GpuScene::build(ctx, &h.view(), &h, &BuildOptions::default()).expect("build");
    (h, scene)
}

fn ctx_or_skip(test: &str) -> Option<Context> {
    context_or_skip(test, Requirement::RayTracing)
}

/// A ray-tracing context opened with `options`, validation on wherever [`ctx_or_skip`]'s
/// context has it (`None` where that skips).
fn ctx_with(test: &str, options: ContextOptions) -> Option<Context> {
    let probe = ctx_or_skip(test)?;
    let validation = if probe.validation_enabled() {
        ValidationRequest::Required
    } else {
        ValidationRequest::Off
    };
    drop(probe);
    let options = ContextOptions {
        validation,
        require: Requirement::RayTracing,
        ..options
    };
    Some(Context::new(&options).expect("context"))
}

fn cpu_render(
    h: &OwnedHierarchy,
    cam: &CameraParams,
    view: View,
    lod: LodParams,
) -> motu_abi::aov::Aov {
    let opts = motu_trace::RenderOptions {
        view: match view {
            View::Shaded => motu_trace::View::Shaded,
            View::Ids => motu_trace::View::Ids,
            View::Lod => motu_trace::View::Lod,
            View::Heatmap => motu_trace::View::Heatmap,
            View::Albedo => motu_trace::View::Albedo,
        },
        lod,
        ..Default::default()
    };
    motu_trace::render(h.view(), h, cam, &opts)
        .expect("cpu render")
        .aov
}

fn backends(ctx: &Context) -> Vec<Backend> {
    let mut b = Vec::new();
    if ctx.caps().ray_pipeline {
        b.push(Backend::Pipeline);
    }
    if ctx.caps().ray_query {
        b.push(Backend::Query);
    }
    b
}

#[test]
fn two_level_hierarchy_matches_the_cpu_oracle_on_both_backends() {
    let Some(ctx) = ctx_or_skip("two_level_matches_cpu") else {
        return;
    };
    let (h, scene) = two_level_scene(&ctx);
    let cam = camera([0.5, 1.0, 7.0], [0.0, 0.0, 0.0], 48);
    let lod = LodParams {
        r_max_px: 12.0,
        ..Default::default()
    };
    let cpu = cpu_render(&h, &cam, View::Shaded, lod);
    let hits = cpu.records.iter().filter(|r| r.mesh != MISS).count();
    assert!(hits > 300, "the camera sees the scene: {hits} hits");
    let lods: std::collections::BTreeSet<u8> = cpu
        .records
        .iter()
        .filter(|r| r.mesh == 0)
        .map(|r| r.lod)
        .collect();
    assert!(!lods.is_empty(), "{lods:?}");
    let mut outputs = Vec::new();
    for backend in backends(&ctx) {
        let out = render(
            &ctx,
            &scene,
            &cam,
            &RenderOptions {
                backend,
                lod,
                view: View::Shaded,
                ..Default::default()
            },
        )
        .expect("render");
        let report =
            motu_trace::compare(&cpu, &out.aov, motu_trace::DEFAULT_REL_EPS).expect("sizes");
        assert!(
            report.mismatched <= 2,
            "{backend:?}: {} of {} pixels differ from the CPU oracle (bbox {:?})",
            report.mismatched,
            report.total,
            report.bbox
        );
        let lod_diff = cpu
            .records
            .iter()
            .zip(&out.aov.records)
            .filter(|(a, b)| a.mesh != MISS && a.mesh == b.mesh && a.lod != b.lod)
            .count();
        assert!(lod_diff <= 2, "{backend:?}: {lod_diff} LOD differences");
        assert_eq!(out.stats.stack_overflows, 0);
        assert!(
            out.stats.shadow_rays > 0 && out.stats.traces_per_ray > 1.0,
            "{:?}",
            out.stats
        );
        assert_eq!(out.rgba8.len(), 48 * 48 * 4);
        outputs.push(out);
    }
    if let [a, b] = &outputs[..] {
        let r = motu_trace::compare(&a.aov, &b.aov, motu_trace::DEFAULT_REL_EPS).expect("sizes");
        assert!(
            r.mismatched <= 1,
            "pipeline vs query: {} differ",
            r.mismatched
        );
    }
    assert_no_validation_errors(&ctx);
}

#[test]
fn ids_view_uses_the_cpu_palette() {
    let Some(ctx) = ctx_or_skip("ids_view_palette") else {
        return;
    };
    let (h, scene) = two_level_scene(&ctx);
    let cam = camera([0.5, 1.0, 7.0], [0.0, 0.0, 0.0], 32);
    let backend = backends(&ctx)[0];
    let out = render(
        &ctx,
        &scene,
        &cam,
        &RenderOptions {
            backend,
            view: View::Ids,
            ..Default::default()
        },
    )
    .expect("render");
    let cpu = motu_trace::render(
        h.view(),
        &h,
        &cam,
        &motu_trace::RenderOptions {
            view: motu_trace::View::Ids,
            ..Default::default()
        },
    )
    .expect("cpu");
    let same = out
        .rgba8
        .chunks_exact(4)
        .zip(cpu.rgba8.chunks_exact(4))
        .filter(|(a, b)| a.iter().zip(b.iter()).all(|(x, y)| x.abs_diff(*y) <= 1))
        .count();
    assert!(
        same >= 32 * 32 - 3,
        "{same} of 1024 pixels share the CPU colour"
    );
    assert_eq!(out.stats.shadow_rays, 0);
    assert_no_validation_errors(&ctx);
}

/// A row of PIs along the view axis: one ray meets many at once.
fn row_of_pis(count: usize) -> OwnedHierarchy {
    let mut b = HierarchyBuilder::new();
    let m = b.mesh(0, 0, 0, uv_sphere(6));
    let blas = b.triangle_blas(&[m]);
    let leaf = b.tlas(&[(srt(0.3, 0.0, [0.0; 3]), blas)]);
    // Leaves wider than their sphere so every box is entered, with holes to see through.
    let ring = b.tlas(&[
        (srt(0.3, 0.0, [1.5, 0.0, 0.0]), blas),
        (srt(0.3, 0.0, [-1.5, 0.0, 0.0]), blas),
    ]);
    let pis: Vec<_> = (0..count)
        .map(|i| {
            (
                srt(1.0, 0.0, [0.0, 0.0, -(i as f32) * 2.5]),
                PiTarget::Tlas(if i + 1 == count { leaf } else { ring }),
            )
        })
        .collect();
    let pb = b.pi_blas(&pis);
    let root = b.tlas(&[(srt(1.0, 0.0, [0.0; 3]), pb)]);
    b.finish(root)
}

#[test]
fn the_payload_holds_as_many_candidates_as_a_tlas_walk_can_meet() {
    // One PI BLAS alone in the root stays in the hardware walk: its PIs, up to 8.
    assert_eq!(crate::scene::pi_capacity(&row_of_pis(3).view(), true), 3);
    assert_eq!(crate::scene::pi_capacity(&row_of_pis(12).view(), true), 8);
    // Beside a triangle instance the PI BLAS is a box list: raygen tests it, no slot needed
    // (streamed skeletons keep it in the hardware walk).
    let mut b = HierarchyBuilder::new();
    let m = b.mesh(0, 0, 0, uv_sphere(6));
    let blas = b.triangle_blas(&[m]);
    let leaf = b.tlas(&[(srt(0.3, 0.0, [0.0; 3]), blas)]);
    let pis: Vec<_> = (0..3)
        .map(|i| {
            (
                srt(1.0, 0.0, [i as f32 * 2.0, 0.0, 0.0]),
                PiTarget::Tlas(leaf),
            )
        })
        .collect();
    let pb = b.pi_blas(&pis);
    let root = b.tlas(&[
        (srt(1.0, 0.0, [0.0, 3.0, 0.0]), blas),
        (srt(1.0, 0.0, [0.0; 3]), pb),
    ]);
    let h = b.finish(root);
    assert_eq!(
        crate::scene::box_list_instances(&h.view(), root as usize),
        1
    );
    assert_eq!(crate::scene::pi_capacity(&h.view(), true), 1);
    assert_eq!(crate::scene::pi_capacity(&h.view(), false), 3);
}

#[test]
fn stack_overflow_is_counted_and_a_larger_stack_removes_it() {
    let Some(ctx) = ctx_or_skip("stack_overflow") else {
        return;
    };
    let h = row_of_pis(12);
    let scene = GpuScene::build(&ctx, &h.view(), &h, &BuildOptions::default()).expect("build");
    // Odd size: the centre ray runs down the row's axis through every ring.
    let cam = camera([0.0, 0.0, 6.0], [0.0, 0.0, -10.0], 15);
    let cpu = cpu_render(&h, &cam, View::Ids, LodParams::default());
    for backend in backends(&ctx).into_iter().rev() {
        let small = render(
            &ctx,
            &scene,
            &cam,
            &RenderOptions {
                backend,
                stack_size: 2,
                view: View::Ids,
                ..Default::default()
            },
        )
        .expect("small stack");
        assert!(
            small.stats.stack_overflows > 0,
            "{backend:?}: {:?}",
            small.stats
        );
        let large = render(
            &ctx,
            &scene,
            &cam,
            &RenderOptions {
                backend,
                stack_size: 32,
                view: View::Ids,
                ..Default::default()
            },
        )
        .expect("large stack");
        assert_eq!(large.stats.stack_overflows, 0, "{backend:?}");
        // More candidates than the payload holds: re-walked, never dropped.
        assert!(
            large.stats.pi_list_overflows > 0,
            "{backend:?}: {:?}",
            large.stats
        );
        let r = motu_trace::compare(&cpu, &large.aov, motu_trace::DEFAULT_REL_EPS).expect("sizes");
        assert!(r.mismatched <= 1, "{backend:?}: {} differ", r.mismatched);
    }
    assert_no_validation_errors(&ctx);
}

#[test]
fn budget_cap_and_compaction() {
    let options = ContextOptions {
        limit_overrides: LimitOverrides {
            max_memory_allocation_count: Some(8),
            ..Default::default()
        },
        ..Default::default()
    };
    let Some(ctx) = ctx_with("budget_cap_and_compaction", options) else {
        return;
    };
    let h = two_level();
    let small = BuildOptions {
        budget_bytes: 64 * 1024,
        max_allocations: 8,
        ..Default::default()
    };
    let err = GpuScene::build(&ctx, &h.view(), &h, &small).expect_err("64 KiB cannot hold it");
    assert!(matches!(err, GpuError::Budget(_)), "{err}");
    assert!(err.to_string().contains("budget"), "{err}");
    assert_eq!(
        ctx.allocation_count(),
        0,
        "a failed build releases everything"
    );
    let opts = BuildOptions {
        budget_bytes: 64 << 20,
        max_allocations: 8,
        staging_bytes: 1 << 20,
        ..Default::default()
    };
    let scene = GpuScene::build(&ctx, &h.view(), &h, &opts).expect("64 MiB");
    let r = scene.report();
    assert!(
        r.peak_allocation_count <= 8 && ctx.peak_allocation_count() <= 8,
        "{r:?}"
    );
    assert!(r.peak_bytes <= r.budget_bytes, "{r:?}");
    // Lavapipe's compacted size equals the built size; NVIDIA compacts to about half.
    assert!(
        r.blas_compacted_bytes <= r.blas_bytes,
        "compaction: {} -> {}",
        r.blas_bytes,
        r.blas_compacted_bytes
    );
    eprintln!(
        "compaction on {}: {} -> {} BLAS bytes",
        ctx.device_name(),
        r.blas_bytes,
        r.blas_compacted_bytes
    );
    assert_eq!(r.blas_count, 4);
    assert_eq!(r.tlas_count, 4);
    assert!(r.scratch_peak_bytes > 0);
    // It renders within the cap too.
    let cam = camera([0.5, 1.0, 7.0], [0.0, 0.0, 0.0], 16);
    let out = render(
        &ctx,
        &scene,
        &cam,
        &RenderOptions {
            backend: backends(&ctx)[0],
            ..Default::default()
        },
    )
    .expect("render");
    assert!(out.stats.allocation_count <= 8);
    assert!(ctx.peak_allocation_count() <= 8);
    assert_no_validation_errors(&ctx);
}

/// One build per batch (`max_batch_result_bytes: 1`): each batch's meshes are loaded and
/// staged while the previous batch builds, through a ring whose halves are smaller than the
/// largest mesh (so staging also flushes mid-batch); meshes shared with earlier batches are
/// not staged again, and the image still matches the CPU oracle.
#[test]
fn uploads_overlap_blas_builds_across_batches() {
    let Some(ctx) = ctx_or_skip("uploads_overlap_blas_builds_across_batches") else {
        return;
    };
    let mut b = HierarchyBuilder::new();
    let green = b.material([0.3, 0.7, 0.4]);
    let meshes: Vec<u32> = (0..5u32)
        .map(|i| b.mesh(i, 0, green, uv_sphere(12 + 6 * i)))
        .collect();
    let mut instances = Vec::new();
    for (i, &m) in meshes.iter().enumerate() {
        let blas = b.triangle_blas(&[m]);
        instances.push((srt(0.45, 0.3 * i as f32, [i as f32 - 2.0, 0.0, 0.0]), blas));
    }
    // Its meshes were staged for earlier batches.
    let shared = b.triangle_blas(&[meshes[0], meshes[4]]);
    instances.push((srt(0.5, 0.0, [0.0, 1.3, 0.0]), shared));
    let root = b.tlas(&instances);
    let h = b.finish(root);
    let opts = BuildOptions {
        max_batch_result_bytes: 1,
        staging_bytes: 64 * 1024,
        ..Default::default()
    };
    let scene = GpuScene::build(&ctx, &h.view(), &h, &opts).expect("build");
    let r = scene.report();
    assert_eq!(r.blas_count, 6, "{r:?}");
    // Six BLAS batches and one TLAS batch.
    assert_eq!(r.build_batches, 7, "{r:?}");
    // Batches 1..=5 were staged while their predecessors built.
    assert_eq!(r.upload_build_overlap_batches, 5, "{r:?}");
    let mesh_bytes = |m: u32| {
        let g = &h.geometry[m as usize];
        (g.positions.len() * 12 + g.indices.len() * 4) as u64
    };
    // Meshes 1..=4 in flight (mesh 0 before the first batch; the shared BLAS stages nothing).
    let expected: u64 = meshes[1..].iter().map(|&m| mesh_bytes(m)).sum();
    assert_eq!(r.upload_overlap_bytes, expected, "{r:?}");
    assert!(
        mesh_bytes(meshes[4]) > 32 * 1024,
        "the largest mesh overflows a ring half"
    );
    assert!(r.upload_overlap_ms > 0.0, "{r:?}");
    let cam = camera([0.0, 0.6, 6.0], [0.0, 0.3, 0.0], 32);
    let cpu = cpu_render(&h, &cam, View::Shaded, LodParams::default());
    let hits = cpu.records.iter().filter(|r| r.mesh != MISS).count();
    assert!(hits > 100, "the camera sees the spheres: {hits} hits");
    let out = render(
        &ctx,
        &scene,
        &cam,
        &RenderOptions {
            backend: backends(&ctx)[0],
            view: View::Shaded,
            ..Default::default()
        },
    )
    .expect("render");
    let cmp = motu_trace::compare(&cpu, &out.aov, motu_trace::DEFAULT_REL_EPS).expect("sizes");
    assert!(
        cmp.mismatched <= 2,
        "{} of {} pixels differ from the CPU oracle",
        cmp.mismatched,
        cmp.total
    );
    drop(scene);
    assert_no_validation_errors(&ctx);
}

/// Fails to load one mesh: with one build per batch, that mesh is staged while an earlier
/// batch is on the GPU.
struct FailingBlobs<'a>(&'a OwnedHierarchy, u32);

impl MeshBlobSource for FailingBlobs<'_> {
    fn mesh_data(
        &self,
        mesh_record: u32,
    ) -> Result<(Cow<'_, [[f32; 3]]>, Cow<'_, [u32]>), MeshSourceError> {
        if mesh_record == self.1 {
            return Err("chunk checksum mismatch".into());
        }
        self.0.mesh_data(mesh_record)
    }
}

#[test]
fn a_load_failure_while_a_batch_builds_releases_everything() {
    let Some(ctx) = ctx_or_skip("a_load_failure_while_a_batch_builds_releases_everything") else {
        return;
    };
    let mut b = HierarchyBuilder::new();
    let red = b.material([0.8, 0.2, 0.2]);
    let mut instances = Vec::new();
    for i in 0..4u32 {
        let m = b.mesh(i, 0, red, uv_sphere(8 + i));
        let blas = b.triangle_blas(&[m]);
        instances.push((srt(0.4, 0.0, [i as f32, 0.0, 0.0]), blas));
    }
    let root = b.tlas(&instances);
    let h = b.finish(root);
    let opts = BuildOptions {
        max_batch_result_bytes: 1,
        ..Default::default()
    };
    let err = GpuScene::build(&ctx, &h.view(), &FailingBlobs(&h, 2), &opts)
        .expect_err("mesh 2 cannot load");
    assert!(
        err.to_string().contains("mesh record 2") && err.to_string().contains("checksum"),
        "{err}"
    );
    assert_eq!(
        ctx.allocation_count(),
        0,
        "a failed build releases everything"
    );
    let scene = GpuScene::build(&ctx, &h.view(), &h, &opts).expect("second build");
    assert_eq!(scene.report().blas_count, 4);
    assert_eq!(scene.report().upload_build_overlap_batches, 3);
    drop(scene);
    assert_no_validation_errors(&ctx);
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct LodCase {
    p: LodParams,
    pixels_per_unit_at_1: f32,
    radius_local: f32,
    dir_local_len: f32,
    t_near: f32,
    level_count: u32,
    ray_kind: u32,
    u: f32,
    _pad: u32,
}

#[test]
fn glsl_camera_and_lod_mirror_the_rust_functions() {
    use crate::tests::{mirror_buffer, run_mirror};
    let Some(ctx) = context_or_skip("glsl_camera_lod_mirror", Requirement::Compute) else {
        return;
    };
    let cams: Vec<CameraParams> = (0..8u32)
        .map(|i| {
            let f = i as f32;
            CameraParams::new(
                [f * 3.1, -f, 100.0 - f * 7.0].into(),
                [0.3 - f * 0.1, -0.2, -1.0 + f * 0.05].into(),
                [0.0, 1.0, 0.1 * f].into(),
                20.0 + f * 11.0,
                i % 2 == 1,
                64 + i * 37,
                48 + i * 13,
            )
        })
        .collect();
    let per_cam = 256u32;
    let mut seed = 12345u32;
    let mut rnd = || {
        seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (seed >> 8) as f32 / (1u32 << 24) as f32
    };
    let cases: Vec<LodCase> = (0..2048)
        .map(|i| LodCase {
            p: LodParams {
                r_max_px: 1.0 + rnd() * 500.0,
                shadow_bias: rnd() * 2.0,
                stochastic: (i % 3 == 0) as u32,
                forced_lod: if i % 7 == 0 { i % 4 } else { -1 },
            },
            pixels_per_unit_at_1: 10.0 + rnd() * 2000.0,
            radius_local: 0.01 + rnd() * 50.0,
            dir_local_len: 0.1 + rnd() * 4.0,
            t_near: rnd() * 1000.0,
            level_count: 1 + (i % 6) as u32,
            ray_kind: (i % 2) as u32,
            u: rnd(),
            _pad: 0,
        })
        .collect();
    let mk = |label: &str, bytes: u64| mirror_buffer(&ctx, label, bytes);
    let cam_buf = mk("cams", (cams.len() * 64) as u64);
    cam_buf.write(0, &cams).expect("write");
    let case_buf = mk("cases", (cases.len() * 48) as u64);
    case_buf.write(0, &cases).expect("write");
    let n_dirs = cams.len() as u32 * per_cam;
    let dir_buf = mk("dirs", u64::from(n_dirs) * 16);
    let lvl_buf = mk("levels", (cases.len() * 4) as u64);
    run_mirror(
        &ctx,
        "abi mirror",
        crate::shaders::TEST_ABI_MIRROR_COMP,
        &[&cam_buf, &case_buf, &dir_buf, &lvl_buf],
        &[cams.len() as u32, per_cam, cases.len() as u32, 0],
        n_dirs.max(cases.len() as u32).div_ceil(64),
    );
    let dirs: Vec<[f32; 4]> = dir_buf.read_vec(0, n_dirs as usize).expect("read");
    let mut max_err = 0f32;
    for (i, d) in dirs.iter().enumerate() {
        let c = &cams[i / per_cam as usize];
        let k = (i as u32) % per_cam;
        let x = (k.wrapping_mul(7919)) % c.width;
        let y = (k.wrapping_mul(104_729)) % c.height;
        let r = c.primary_dir(x, y, 0.5, 0.5);
        for (a, b) in r.to_array().iter().zip(d) {
            max_err = max_err.max((a - b).abs());
        }
    }
    assert!(
        max_err <= 4.0 * f32::EPSILON,
        "camera directions differ by up to {max_err}"
    );
    let levels: Vec<u32> = lvl_buf.read_vec(0, cases.len()).expect("read");
    let mut differ = 0;
    for (c, &gpu) in cases.iter().zip(&levels) {
        let cpu = motu_abi::lod::select_lod(
            &c.p,
            c.pixels_per_unit_at_1,
            c.radius_local,
            c.dir_local_len,
            c.t_near,
            c.level_count,
            c.ray_kind,
            c.u,
        );
        if cpu != gpu {
            // Only where log2's last-bit rounding can cross an integer (or the dither threshold).
            let px =
                (c.radius_local / c.dir_local_len) * c.pixels_per_unit_at_1 / c.t_near.max(1e-6);
            let level = (c.p.r_max_px / px).log2();
            let frac = level - level.floor();
            assert!(
                !(1e-4..=1.0 - 1e-4).contains(&frac) || (frac - c.u).abs() < 1e-4,
                "{cpu} vs {gpu}"
            );
            differ += 1;
        }
    }
    assert!(differ <= 4, "{differ} LOD levels differ");
    assert_no_validation_errors(&ctx);
}

/// `ContextOptions::pipeline_stats`: every trace pipeline made (both backends, full and
/// streamed variants) is in the context's log under its label; with
/// `VK_KHR_pipeline_executable_properties` each has executables with statistics, without it
/// (lavapipe, Mesa 25.0) each has none and the context says so (a warning, never an error).
#[test]
fn pipeline_stats_per_backend_and_variant() {
    let options = ContextOptions {
        pipeline_stats: true,
        ..Default::default()
    };
    let Some(ctx) = ctx_with("pipeline_stats_per_backend_and_variant", options) else {
        return;
    };
    assert!(ctx.pipeline_stats_requested());
    assert_eq!(
        ctx.pipeline_stats_enabled(),
        ctx.caps().pipeline_executable_info
    );
    let (_, scene) = two_level_scene(&ctx);
    let cam = camera([0.5, 1.0, 7.0], [0.0, 0.0, 0.0], 16);
    let backends = backends(&ctx);
    for &backend in &backends {
        let opts = RenderOptions {
            backend,
            ..Default::default()
        };
        render(&ctx, &scene, &cam, &opts).expect("render");
        // The streamed variant, made as the stream renderer's `ensure_tracer` makes it.
        let mut heap = scene.heap();
        let t =
            super::Tracer::new(&ctx, &mut heap, &opts, 4, true, false).expect("streamed tracer");
        let own = match &t {
            super::Tracer::Pipeline(p) => p.executable_stats().cloned(),
            super::Tracer::Query(q) => q.executable_stats().cloned(),
        };
        t.release(&mut heap);
        assert_eq!(own.is_some(), ctx.pipeline_stats_enabled(), "{backend:?}");
    }
    let captured = ctx.captured_pipelines();
    for label in ["trace full", "trace streamed"] {
        let made: Vec<_> = captured.iter().filter(|p| p.label == label).collect();
        let kinds: Vec<_> = made.iter().map(|p| p.kind).collect();
        let want: Vec<_> = backends
            .iter()
            .map(|b| match b {
                Backend::Pipeline => "ray_tracing",
                Backend::Query => "compute",
            })
            .collect();
        assert_eq!(kinds, want, "{label}: one pipeline a backend");
        for p in made {
            assert_eq!(p.raygen_stack_bytes.is_some(), p.kind == "ray_tracing");
            eprintln!(
                "{label} ({}) on {}: raygen stack {:?} bytes",
                p.kind,
                ctx.device_name(),
                p.raygen_stack_bytes
            );
            match &p.stats {
                Some(s) => {
                    assert!(!s.executables.is_empty(), "{label} {}", p.kind);
                    assert!(
                        s.executables.iter().any(|e| !e.statistics.is_empty()),
                        "{label} {}: no statistic",
                        p.kind
                    );
                    for e in &s.executables {
                        eprintln!("  {} {:?}: {:?}", e.name, e.stages, e.statistics);
                    }
                }
                None => assert!(!ctx.pipeline_stats_enabled(), "{label}: none captured"),
            }
        }
    }
    if !ctx.pipeline_stats_enabled() {
        eprintln!(
            "pipeline stats: {} lacks VK_KHR_pipeline_executable_properties: checked the \
             warning/None path only (pipelines logged without statistics)",
            ctx.device_name()
        );
    }
    drop(scene);
    assert_no_validation_errors(&ctx);
}

/// Without the option nothing is captured or logged.
#[test]
fn pipeline_stats_off_by_default() {
    let Some(ctx) = ctx_or_skip("pipeline_stats_off_by_default") else {
        return;
    };
    assert!(!ctx.pipeline_stats_requested() && !ctx.pipeline_stats_enabled());
    let (_, scene) = two_level_scene(&ctx);
    let cam = camera([0.5, 1.0, 7.0], [0.0, 0.0, 0.0], 8);
    render(&ctx, &scene, &cam, &RenderOptions::default()).expect("render");
    assert!(ctx.captured_pipelines().is_empty());
}
