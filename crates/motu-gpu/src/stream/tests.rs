//! GPU tests of the streaming renderer (lavapipe, validation on, small images): AOV equality
//! with a full build under a budget 4× smaller than the full build, the budget never exceeded,
//! and a camera path whose later frames need ~1 pass and build far fewer triangles than
//! rebuilding everything per frame.

use motu_abi::aov::{Aov, MISS};
use motu_abi::camera::{camera_path, CameraPath, CameraPose};
use motu_trace::testutil::{srt, uv_sphere, HierarchyBuilder, OwnedHierarchy, PiTarget};

use crate::testutil::{assert_no_validation_errors, context_or_skip};
use crate::{
    render, Backend, BuildOptions, Context, FrameStreamStats, GpuScene, RenderOptions,
    RenderOutput, Requirement, StreamOptions, StreamingRenderer, View,
};

/// `field` made to exercise the whole shading model: every sphere gets smooth normals and
/// texture coordinates, every other material an 8×8 checker texture with mips (2 levels), and
/// a few materials are metallic, rough or emissive.
fn textured_field(rows: u32, cols: u32, segments: u32) -> OwnedHierarchy {
    textured(field(rows, cols, segments))
}

/// `h` made to exercise the whole shading model, as [`textured_field`] says.
fn textured(mut h: OwnedHierarchy) -> OwnedHierarchy {
    for (m, g) in h.meshes.iter_mut().zip(h.geometry.iter_mut()) {
        g.normals = Some(g.positions.clone());
        g.uvs = Some(
            g.positions
                .iter()
                .map(|p| {
                    [
                        0.5 + p[2].atan2(p[0]) / std::f32::consts::TAU,
                        0.5 + 0.5 * p[1],
                    ]
                })
                .collect(),
        );
        m.flags |= motu_abi::FLAG_HAS_NORMALS | motu_abi::FLAG_HAS_UVS;
    }
    let mut texels = Vec::new();
    for (size, a, b) in [
        (8u32, 0xff20_40e0u32, 0xffe0_e0e0u32),
        (4, 0xff80_80e0, 0xff80_80e0),
    ] {
        for y in 0..size {
            for x in 0..size {
                texels.push(if (x + y) % 2 == 0 { a } else { b });
            }
        }
    }
    h.texels = texels;
    h.textures = vec![motu_abi::TextureRecord {
        texel_offset: 0,
        width: 8,
        height: 8,
        mip_count: 2,
    }];
    for (i, mat) in h.materials.iter_mut().enumerate() {
        if i % 2 == 1 {
            mat.base_color_texture = 0;
        }
        mat.roughness = 0.2 + 0.1 * (i % 8) as f32;
        mat.metallic = if i % 5 == 0 { 1.0 } else { 0.0 };
        if i % 13 == 0 {
            mat.emission = [0.05, 0.02, 0.0];
        }
    }
    h
}

/// The full shading model's inputs: a distant and a point light, a sky with ambient occlusion
/// (2 rays per sample, reaching 3 units) and 2 samples per pixel.
/// `h` with a checker texture of its own per material (each BLAS of a field then streams one
/// texture with its mesh).
fn per_material_textures(mut h: OwnedHierarchy) -> OwnedHierarchy {
    h.textures.clear();
    h.texels.clear();
    for (i, mat) in h.materials.iter_mut().enumerate() {
        let a = 0xff00_0000u32 | (i as u32 * 0x0003_0507);
        let b = 0xffff_ffffu32 ^ (i as u32 * 0x0001_0203);
        h.textures.push(motu_abi::TextureRecord {
            texel_offset: h.texels.len() as u32,
            width: 4,
            height: 4,
            mip_count: 1,
        });
        for y in 0..4u32 {
            for x in 0..4u32 {
                h.texels.push(if (x + y) % 2 == 0 { a } else { b });
            }
        }
        mat.base_color_texture = i as u32;
    }
    h
}

/// Shaded frames without AO, one sample a pixel: textures, normals, lights and shadow rays
/// (the tests of what streams with meshes).
fn textured_opts(be: Backend) -> RenderOptions {
    RenderOptions {
        shading: motu_abi::shade::Shading {
            ao_samples: 0,
            spp: 1,
            ..full_shading()
        },
        ..ids_opts(be)
    }
}

fn full_shading() -> motu_abi::shade::Shading {
    use motu_abi::shade::{LightRecord, Shading, LIGHT_DISTANT, LIGHT_POINT};
    let mut s = Shading {
        light_count: 2,
        sky: Some([0.25, 0.3, 0.4]),
        ao_samples: 2,
        ao_distance: 3.0,
        spp: 2,
        exposure_ev: 0.5,
        ..Default::default()
    };
    let d = [-0.5f32, -0.7, -0.5];
    let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    s.lights[0] = LightRecord {
        kind: LIGHT_DISTANT,
        world_direction: d.map(|c| c / l),
        radiance: [2.0, 1.9, 1.7],
        ..Default::default()
    };
    s.lights[1] = LightRecord {
        kind: LIGHT_POINT,
        world_position: [1.5, 2.5, 3.0],
        radiance: [12.0, 10.0, 8.0],
        ..Default::default()
    };
    s
}

/// A field of `rows × cols` distinct sphere meshes (each its own BLAS): the root holds a few
/// direct triangle instances (root proxies) and a PI BLAS over one child TLAS per row (child
/// TLASes stream in), one row behind the other so near rows occlude far ones.
fn field(rows: u32, cols: u32, segments: u32) -> OwnedHierarchy {
    field_with_ground(rows, cols, segments, false)
}

/// [`field`], with a ground under it when `ground` (a sphere of radius 100 whose top touches
/// the spheres' bottoms: most diffuse bounces off the field then hit something).
fn field_with_ground(rows: u32, cols: u32, segments: u32, ground: bool) -> OwnedHierarchy {
    let mut b = HierarchyBuilder::new();
    let mut row_tlases = Vec::new();
    let mut mesh_id = 0;
    for r in 0..rows {
        let mut instances = Vec::new();
        for c in 0..cols {
            let mat = b.material([0.3 + 0.05 * c as f32, 0.5, 0.9 - 0.05 * r as f32]);
            let m = b.mesh(mesh_id, 0, mat, uv_sphere(segments + (mesh_id % 3)));
            mesh_id += 1;
            let blas = b.triangle_blas(&[m]);
            let x = (c as f32 - (cols - 1) as f32 / 2.0) * 2.1;
            instances.push((srt(1.0, 0.3 * c as f32, [x, 0.0, 0.0]), blas));
        }
        row_tlases.push(b.tlas(&instances));
    }
    let pis: Vec<_> = row_tlases
        .iter()
        .enumerate()
        .map(|(r, &t)| {
            let z = -(r as f32) * 2.2;
            let y = 0.2 * (r % 2) as f32;
            (srt(1.0, 0.0, [0.0, y, z]), PiTarget::Tlas(t))
        })
        .collect();
    let pi_blas = b.pi_blas(&pis);
    let mut root = vec![(srt(1.0, 0.0, [0.0, 0.0, 0.0]), pi_blas)];
    for k in 0..3u32 {
        let m = b.mesh(mesh_id, 0, 0, uv_sphere(segments));
        mesh_id += 1;
        let blas = b.triangle_blas(&[m]);
        root.push((srt(0.8, 0.0, [-4.0 + 4.0 * k as f32, -1.5, 3.0]), blas));
    }
    if ground {
        let mat = b.material([0.7, 0.65, 0.6]);
        let m = b.mesh(mesh_id, 0, mat, uv_sphere(segments));
        let blas = b.triangle_blas(&[m]);
        root.push((srt(100.0, 0.0, [0.0, -101.0, 0.0]), blas));
    }
    let root_tlas = b.tlas(&root);
    b.finish(root_tlas)
}

/// Bytes the full build holds at its peak (live allocations: with an unlimited budget its
/// blocks are 256 MiB each, which says nothing about the scene).
fn full_build_needs(full: &GpuScene) -> u64 {
    let r = full.report();
    let Some(a) = r.alloc.as_ref() else {
        return r.peak_bytes;
    };
    // As on unified memory (lavapipe, where the budgets below were chosen): with host memory
    // apart (a discrete GPU, MOTU_SIMULATE_DISCRETE_MEMORY) the full build's staging is not in
    // its budgeted peak, and fractions of that fall below what these scenes' streamers need.
    a.peak_in_use_bytes
        + a.classes
            .values()
            .filter(|c| !c.counts_against_budget)
            .map(|c| c.peak_in_use_bytes)
            .sum::<u64>()
}

/// The camera path of the path tests: a 70° yaw sweep with a 4-unit dolly.
const SWEEP: CameraPath = CameraPath {
    yaw_sweep_deg: 70.0,
    dolly_world: 4.0,
};

fn base_pose() -> CameraPose {
    CameraPose {
        world_eye: [0.0, 0.1, 7.0].into(),
        world_forward: [0.0, -0.02, -1.0].into(),
        world_up: [0.0, 1.0, 0.0].into(),
        fov_deg: 40.0,
        mirror_x: false,
    }
}

fn backend(ctx: &Context) -> Backend {
    Backend::best(ctx).unwrap_or(Backend::Pipeline)
}

fn ids_opts(backend: Backend) -> RenderOptions {
    RenderOptions {
        backend,
        view: View::Shaded,
        ..Default::default()
    }
}

const SIZE: u32 = 48;

/// The streamed AOV equals the full build's, per pixel (mesh, primitive, depth).
fn assert_same_aov(full: &Aov, streamed: &Aov, what: &str) {
    let cmp = motu_trace::compare(full, streamed, motu_trace::DEFAULT_REL_EPS).expect("sizes");
    assert_eq!(
        cmp.mismatched, 0,
        "{what}: {} of {} pixels differ from the full build",
        cmp.mismatched, cmp.total
    );
}

/// Streamed shaded colours against the full build's: the same shader code runs the same float
/// operations in the same order, so they must be equal; the tolerance (one 8-bit step on at most
/// 0.5% of the pixels) only covers a compiler contracting a multiply-add differently where the
/// two paths inline it, never a missing term (a shadow, a texture, an AO ray changes far more).
fn assert_shaded_equal(full: &[u8], streamed: &[u8], what: &str) {
    assert_eq!(full.len(), streamed.len());
    let mut off = 0usize;
    for (a, b) in full.iter().zip(streamed) {
        let d = a.abs_diff(*b);
        assert!(d <= 1, "{what}: a channel differs by {d} (> 1)");
        off += usize::from(d != 0);
    }
    eprintln!(
        "{what}: {off} of {} colour channels differ by one step",
        full.len()
    );
    assert!(
        off * 200 <= full.len(),
        "{what}: {off} of {} channels differ",
        full.len()
    );
}

/// The traversal backends this device runs (both on lavapipe; the pipeline alone on NVIDIA).
fn available_backends(ctx: &Context) -> Vec<Backend> {
    let caps = ctx.caps();
    [
        (caps.ray_pipeline, Backend::Pipeline),
        (caps.ray_query, Backend::Query),
    ]
    .into_iter()
    .filter_map(|(ok, be)| ok.then_some(be))
    .collect()
}

/// Streaming options for the small test scenes: a budget of a few MiB, with staging and
/// scratch kept small so the budget holds structures rather than rings.
fn small_stream_options(budget: u64) -> StreamOptions {
    StreamOptions {
        budget_bytes: budget,
        staging_bytes: 256 * 1024,
        scratch_budget_bytes: 1 << 20,
        ..Default::default()
    }
}
/// [`small_stream_options`] with meshes in VRAM on any device, for tests of what evicting and
/// draining them does (on a discrete GPU `MeshMemory::Auto` keeps them in host memory).
fn device_meshes(budget: u64) -> StreamOptions {
    StreamOptions {
        mesh_memory: crate::MeshMemory::Device,
        ..small_stream_options(budget)
    }
}

/// [`small_stream_options`] with no guard band (no prefetch): a cold renderer's first pass
/// builds nothing ahead of what the image's own rays meet.
fn no_guard_band(budget: u64) -> StreamOptions {
    StreamOptions {
        guard_band_px: 0,
        ..small_stream_options(budget)
    }
}

/// Frame `f` of the [`SWEEP`] path in `frames` frames, and from `f = frames` on at rest where
/// the path ended.
fn sweep_then_rest(f: u32, frames: u32) -> motu_abi::camera::CameraParams {
    camera_path(&base_pose(), &SWEEP, f.min(frames - 1), frames).params(SIZE, SIZE)
}

/// A test's context, hierarchy and the hierarchy's full build (what streamed frames are
/// compared with).
struct Fixture {
    ctx: Context,
    h: OwnedHierarchy,
    full: GpuScene,
}

impl Fixture {
    /// `None` where no device runs the tests (`context_or_skip` says so).
    fn new(test: &str, h: OwnedHierarchy) -> Option<Self> {
        let ctx = context_or_skip(test, Requirement::RayTracing)?;
        let full = GpuScene::build(&ctx, &h.view(), &h, &BuildOptions::default()).expect("full");
        Some(Self { ctx, h, full })
    }
}

/// A streaming renderer of `h` (its own mesh source).
fn streamer<'a>(
    ctx: &Context,
    h: &'a OwnedHierarchy,
    opts: &StreamOptions,
) -> StreamingRenderer<'a> {
    StreamingRenderer::new(ctx, h.view(), h, opts).expect("streaming renderer")
}

/// `View::Ids` (mesh and primitive ids, no shading) on `backend`.
fn ids_view_opts(backend: Backend) -> RenderOptions {
    RenderOptions {
        backend,
        view: View::Ids,
        ..Default::default()
    }
}

/// Half the full build with the coarse fallback and a frame build budget of about two small
/// spheres: a frame of the field stops early and later frames of the same camera refine.
fn refining_options(full: &GpuScene) -> StreamOptions {
    StreamOptions {
        budget_bytes: full_build_needs(full) / 2,
        fallback: crate::StreamFallback::Coarse,
        frame_build_bytes: 64 * 1024,
        // These tests follow the refinement frame by frame at a camera at rest.
        settle_after_still_frames: 0,
        ..Default::default()
    }
}

/// The next frame of a camera at rest: a whole frame, or a progressive one (one trace, then a
/// bounded build for the next frame).
fn refine(
    sr: &mut StreamingRenderer<'_>,
    progressive: bool,
    cam: &motu_abi::camera::CameraParams,
    opts: &RenderOptions,
) -> (RenderOutput, FrameStreamStats) {
    if progressive {
        sr.render_progressive(cam, opts)
    } else {
        sr.render_frame(cam, opts)
    }
    .expect("frame")
}

#[test]
fn streaming_under_a_quarter_of_the_full_build_matches_it_on_both_backends() {
    let Some(Fixture { ctx, h, full }) =
        Fixture::new("streaming_matches_full_build", textured_field(10, 16, 30))
    else {
        return;
    };
    let full_needs = full_build_needs(&full);
    let budget = full_needs / 4;
    eprintln!("full build needs {full_needs} bytes; streaming budget {budget} bytes");
    let cam = base_pose().params(SIZE, SIZE);
    let backends = available_backends(&ctx);
    for be in backends {
        let opts = ids_opts(be);
        let reference = render(&ctx, &full, &cam, &opts).expect("full render");
        let hits = reference
            .aov
            .records
            .iter()
            .filter(|r| r.mesh != MISS)
            .count();
        assert!(hits > 400, "the camera sees the field: {hits}");
        let mut sr = streamer(&ctx, &h, &small_stream_options(budget));
        let (out, st) = sr.render_frame(&cam, &opts).expect("stream frame");
        eprintln!("{be:?}: {st:?}");
        assert!(st.complete, "{st:?}");
        assert!(
            st.passes >= 2,
            "lazy: the first pass meets empty instances: {st:?}"
        );
        assert!(st.blas_built > 0, "{st:?}");
        let cmp = motu_trace::compare(&reference.aov, &out.aov, motu_trace::DEFAULT_REL_EPS)
            .expect("sizes");
        assert!(
            cmp.fraction <= 0.001,
            "{be:?}: mismatch {} of {}",
            cmp.mismatched,
            cmp.total
        );
        // The full shading model (textures, smooth normals, two lights with shadow rays, AO,
        // 2 spp): resolved while each hit's BLAS is resident and its secondary rays deferred
        // like primary rays, streaming at a quarter of the full build must give the full
        // build's colours (same rays, same random numbers, same arithmetic).
        let shaded = RenderOptions {
            shading: full_shading(),
            ..opts
        };
        // Smaller: every pixel traces up to 2 × (1 + 2 + 2) rays, slow under validation.
        let small = base_pose().params(32, 32);
        let full_shaded = render(&ctx, &full, &small, &shaded).expect("full shaded render");
        // A cold renderer: its secondary rays meet structures not built yet and are deferred.
        let mut cold = streamer(&ctx, &h, &no_guard_band(budget));
        let (out_shaded, st_shaded) = cold.render_frame(&small, &shaded).expect("stream shaded");
        drop(cold);
        assert!(st_shaded.passes >= 2, "{st_shaded:?}");
        eprintln!("{be:?} shaded: {st_shaded:?}");
        assert!(st_shaded.complete, "{st_shaded:?}");
        let cmp = motu_trace::compare(&full_shaded.aov, &out_shaded.aov, 0.0).expect("sizes");
        assert_eq!(
            cmp.mismatched, 0,
            "{be:?}: the shaded frame's AOV equals the full build's"
        );
        assert_shaded_equal(&full_shaded.rgba8, &out_shaded.rgba8, &format!("{be:?}"));
        assert!(
            out_shaded.stats.shadow_rays > 0,
            "secondary rays were traced: {:?}",
            out_shaded.stats
        );
        let alloc = sr.alloc_report();
        assert!(
            alloc.peak_block_bytes <= budget,
            "peak {} > budget {budget}",
            alloc.peak_block_bytes
        );
        assert!(st.vram_peak_bytes <= st.vram_budget_bytes);
        assert!(
            full_needs >= 4 * alloc.budget_bytes,
            "the full build needs >= 4x the streaming budget"
        );
        // Not everything was built: only what rays touched.
        let totals = sr.totals();
        assert!(
            totals.triangles_built < totals.scene_triangles,
            "{totals:?}"
        );
    }
    assert_no_validation_errors(&ctx);
}

/// Issue 16: image textures stream with the meshes that sample them. Every material of the
/// field samples its own texture; at a quarter of the full build's bytes on a camera path,
/// only the textures of resident meshes are resident (at most one per resident BLAS here), some
/// were let go with evicted meshes, and every frame's hits and colours equal the full build's.
#[test]
fn textures_stream_with_the_meshes_that_sample_them() {
    let Some(Fixture { ctx, h, full }) = Fixture::new(
        "stream_textures",
        per_material_textures(textured_field(10, 16, 30)),
    ) else {
        return;
    };
    let budget = full_build_needs(&full) / 4;
    let shaded = textured_opts(backend(&ctx));
    let mut sr = streamer(&ctx, &h, &small_stream_options(budget));
    let path = SWEEP;
    let frames = 4;
    let mut resident_textures = Vec::new();
    for f in 0..frames {
        let cam = camera_path(&base_pose(), &path, f, frames).params(32, 32);
        let (out, st) = sr.render_frame(&cam, &shaded).expect("frame");
        assert!(st.complete, "{st:?}");
        assert!(st.vram_peak_bytes <= budget, "{st:?}");
        // Here every BLAS holds one mesh of one material with one texture.
        assert!(
            st.resident_textures >= 1 && st.resident_textures <= st.resident_blases,
            "textures follow the resident meshes: {st:?}"
        );
        resident_textures.push(st.resident_textures);
        let reference = render(&ctx, &full, &cam, &shaded).expect("full render");
        let cmp = motu_trace::compare(&reference.aov, &out.aov, 0.0).expect("sizes");
        assert_eq!(cmp.mismatched, 0, "frame {f}: hits equal the full build's");
        assert_shaded_equal(&reference.rgba8, &out.rgba8, &format!("frame {f}"));
    }
    let totals = sr.totals();
    eprintln!(
        "resident textures per frame {resident_textures:?} of {}; {totals:?}",
        h.textures.len()
    );
    assert!(
        resident_textures
            .iter()
            .all(|&n| (n as usize) < h.textures.len()),
        "only what the resident meshes sample is resident"
    );
    assert!(
        totals.evicted > 0,
        "meshes (and their textures) were let go"
    );
    drop(sr);
    assert_no_validation_errors(&ctx);
}

#[test]
fn camera_path_reuses_last_frames_structures_and_evicts_under_the_budget() {
    let Some(Fixture { ctx, h, full }) = Fixture::new("stream_camera_path", field(10, 16, 30))
    else {
        return;
    };
    let budget = full_build_needs(&full) / 4;
    let be = backend(&ctx);
    let opts = ids_opts(be);
    let mut sr = streamer(&ctx, &h, &small_stream_options(budget));
    let frames = 30;
    let path = SWEEP;
    let mut passes_after_first = 0u32;
    let mut mismatched = 0u64;
    let mut total = 0u64;
    for f in 0..frames {
        let cam = camera_path(&base_pose(), &path, f, frames).params(SIZE, SIZE);
        let (out, st) = sr.render_frame(&cam, &opts).expect("frame");
        eprintln!("frame {f}: {st:?}");
        assert!(st.complete, "{st:?}");
        assert!(st.vram_peak_bytes <= budget);
        if f > 0 {
            passes_after_first += st.passes;
        }
        // Every 5th frame against the full build (the CPU oracle agrees with it elsewhere).
        if f % 5 == 4 {
            let reference = render(&ctx, &full, &cam, &opts).expect("full render");
            let cmp = motu_trace::compare(&reference.aov, &out.aov, motu_trace::DEFAULT_REL_EPS)
                .expect("sizes");
            mismatched += cmp.mismatched;
            total += cmp.total;
        }
    }
    let totals = sr.totals();
    let avg = f64::from(passes_after_first) / f64::from(frames - 1);
    let full_every_frame = totals.scene_triangles * u64::from(frames);
    let ratio = full_every_frame as f64 / totals.triangles_built.max(1) as f64;
    eprintln!(
        "path: {frames} frames, average passes after the first {avg:.3}, triangles built {} vs \
         {full_every_frame} rebuilding everything per frame ({ratio:.1}x), evicted {}, peak {} of \
         {budget}",
        totals.triangles_built, totals.evicted, totals.vram_peak_bytes
    );
    assert!(
        mismatched as f64 <= 0.001 * total as f64,
        "{mismatched} of {total}"
    );
    // Issue 14 item 6 (≤ 1.3) is asserted on the default island in
    // tests/tests/stream_bounded.rs (1.10 there). This fixture's working set nearly fills a
    // quarter budget: it measures 1.345, the extra passes being spheres disoccluded between
    // nearer ones (no guard-band ray sees them coming) and BLASes that rays enter but never
    // hit (only hits refresh an LRU age), evicted and needed again. Keeping recently needed
    // BLASes (tried) evicts others instead at this budget; see notes/s3-issue-14-17-interactive.md.
    // With the mark walk (marks only in front of a ray's hit) it measures 1.379: one more
    // disocclusion pass in 29 frames, which marks behind the hits had prefetched by chance
    // (marking everything a guard ray passes, hit or not, measured 1.586: the prefetch then
    // crowds out what the next frames need).
    assert!(avg <= 1.4, "average passes after the first frame: {avg}");
    assert!(ratio >= 3.0, "{ratio}");
    assert!(totals.vram_peak_bytes <= budget);
    let report = sr.alloc_report();
    assert!(report.peak_block_bytes <= budget);
    // Structures of about a block get blocks of their own (`dedicated_above_bytes`): free
    // space stranded inside device blocks stays within a few blocks.
    let dl = &report.classes[&motu_alloc::MemoryClass::DeviceLocal];
    eprintln!(
        "device-local blocks {} B, in use {} B, standard block {} B",
        dl.block_bytes, dl.in_use_bytes, dl.standard_block_bytes
    );
    assert!(
        dl.free_bytes <= 4 * dl.standard_block_bytes,
        "{} B free inside {} B of blocks",
        dl.free_bytes,
        dl.block_bytes
    );
    assert_no_validation_errors(&ctx);
}

/// Regression (issue 8): a pass whose requests exceed what is free built nothing and failed
/// with "0 resident" on a generated island. Now a budget of 1/16 of the full build still
/// completes the frame: each pass builds what fits, most requested first, evicting what only
/// already-completed pixels used, and the image equals the full build's.
#[test]
fn a_frame_under_a_sixteenth_of_the_full_build_evicts_mid_frame_and_completes() {
    let Some(Fixture { ctx, h, full }) = Fixture::new("stream_pass_over_budget", field(10, 16, 30))
    else {
        return;
    };
    let budget = full_build_needs(&full) / 16;
    let opts = ids_opts(backend(&ctx));
    let cam = base_pose().params(SIZE, SIZE);
    let reference = render(&ctx, &full, &cam, &opts).expect("full render");
    let mut sr = StreamingRenderer::new(
        &ctx,
        h.view(),
        &h,
        &StreamOptions {
            budget_bytes: budget,
            ..Default::default()
        },
    )
    .expect("streaming renderer (staging and scratch sized from the budget)");
    let (out, st) = sr.render_frame(&cam, &opts).expect("stream frame");
    eprintln!("{st:?}");
    assert!(st.complete, "{st:?}");
    assert!(
        st.evicted > 0,
        "the frame's set does not fit at once: {st:?}"
    );
    assert!(st.vram_peak_bytes <= budget, "{st:?}");
    // The time breakdown (`--stats`): one entry per pass, builds accounted to their pass (or
    // the prefetch), the parts of the build time inside it, the working set counted.
    assert_eq!(st.pass_log.len(), st.passes as usize, "{st:?}");
    let per_pass: u32 = st.pass_log.iter().map(|p| p.blas_built).sum();
    assert_eq!(per_pass + st.prefetched, st.blas_built, "{st:?}");
    assert!(
        st.mesh_ms + st.blas_ms + st.tlas_ms + st.tables_ms <= st.build_ms * 1.001 + 0.1,
        "{st:?}"
    );
    assert!(
        st.working_set_blases > 0 && st.working_set_bytes > 0,
        "{st:?}"
    );
    // Evictions: the passes' are part of the frame's (the prefetch after the last pass may
    // evict too), their causes are parts of them and each is counted in its pass, and what
    // they released is counted.
    let per_pass: u32 = st.pass_log.iter().map(|p| p.evicted).sum();
    assert!(per_pass <= st.evicted, "{st:?}");
    let causes = |p: &crate::stream::PassStats| p.evicted_for_tlas + p.evicted_on_refusal;
    assert!(st.pass_log.iter().all(|p| causes(p) <= p.evicted), "{st:?}");
    assert!(
        st.evicted_for_tlas + st.evicted_on_refusal <= st.evicted,
        "{st:?}"
    );
    assert_eq!(
        st.pass_log.iter().map(causes).sum::<u32>(),
        st.evicted_for_tlas + st.evicted_on_refusal,
        "every cause counted in some pass: {st:?}"
    );
    assert!(
        st.evicted_bytes >= u64::from(st.evicted) * 64,
        "evicted structures released their bytes: {st:?}"
    );
    // Bytes per pass: parts of the frame's, present wherever the pass built or evicted.
    let built: u64 = st.pass_log.iter().map(|p| p.built_bytes).sum();
    let released: u64 = st.pass_log.iter().map(|p| p.evicted_bytes).sum();
    assert!(
        built <= st.built_bytes && released <= st.evicted_bytes,
        "{st:?}"
    );
    assert!(
        st.pass_log
            .iter()
            .all(|p| (p.blas_built > 0) == (p.built_bytes > 0)
                && (p.evicted > 0) <= (p.evicted_bytes > 0)),
        "{st:?}"
    );
    // A TLAS rebuild that does not fit gives back builds a 32nd of the budget at a time, not
    // one per attempt (each attempt re-encodes every resident instance).
    assert!(
        st.tlas_builds <= 4 * st.tlas_rebuilt.max(1),
        "{} TLAS builds for {} rebuilds",
        st.tlas_builds,
        st.tlas_rebuilt
    );
    let cmp =
        motu_trace::compare(&reference.aov, &out.aov, motu_trace::DEFAULT_REL_EPS).expect("sizes");
    assert!(cmp.fraction <= 0.001, "{} of {}", cmp.mismatched, cmp.total);
    assert_no_validation_errors(&ctx);
}

/// Issue 14 item 5 / issue 17 item 3: a per-frame build budget far below the frame's working
/// set stops the first frame early; with the coarse fallback its unfinished pixels show the
/// bounds of what is missing (counted, LOD marked `LOD_FALLBACK`), later frames of the same
/// camera refine, and the path converges to the full build's exact image. `render_progressive`
/// (one trace, then a bounded build for the next frame) converges the same way.
#[test]
fn a_frame_build_budget_shows_the_fallback_then_converges_to_the_full_build() {
    let Some(Fixture { ctx, h, full }) = Fixture::new("stream_fallback", field(10, 16, 30)) else {
        return;
    };
    let opts = ids_opts(backend(&ctx));
    let cam = base_pose().params(SIZE, SIZE);
    let reference = render(&ctx, &full, &cam, &opts).expect("full render");
    for progressive in [false, true] {
        let mut sr = streamer(&ctx, &h, &refining_options(&full));
        let mut frames = Vec::new();
        let mut last = None;
        for _ in 0..200 {
            let (out, st) = refine(&mut sr, progressive, &cam, &opts);
            assert!(st.built_bytes > 0 || st.complete, "{st:?}");
            let done = st.complete;
            if frames.is_empty() {
                // Primary rays that met a missing structure show its bounds, marked.
                let marked = out
                    .aov
                    .records
                    .iter()
                    .filter(|r| r.lod == motu_abi::aov::LOD_FALLBACK)
                    .count() as u64;
                assert!(
                    marked > 0 && marked <= st.fallback_pixels,
                    "{marked} {st:?}"
                );
            }
            frames.push(st);
            last = Some(out);
            if done {
                break;
            }
        }
        let first = &frames[0];
        eprintln!(
            "progressive {progressive}: first {first:?}, {} frames",
            frames.len()
        );
        assert!(!first.complete && first.fallback_pixels > 0, "{first:?}");
        assert_eq!(first.fallback_pixels, first.incomplete_pixels);
        assert!(first.build_budget_spent || progressive, "{first:?}");
        if progressive {
            assert_eq!(first.passes, 1, "{first:?}");
        }
        assert!(frames.len() > 2, "refined over several frames");
        let out = last.expect("a frame");
        let st = frames.last().expect("a frame");
        assert!(
            st.complete && st.fallback_pixels == 0,
            "never converged: {st:?}"
        );
        let cmp = motu_trace::compare(&reference.aov, &out.aov, motu_trace::DEFAULT_REL_EPS)
            .expect("sizes");
        assert_eq!(cmp.mismatched, 0, "{cmp:?}");
        let totals = sr.totals();
        assert!(totals.fallback_pixels >= first.fallback_pixels);
    }
    assert_no_validation_errors(&ctx);
}

/// Issue 45.6 (notes/flight.md D2, D3): on the whole-frame clock, with counts for times
/// (`FrameCaps`: one BLAS and one stale TLAS piece a frame) and with a clock that is always out
/// of time (`frame_ms` of a microsecond: each frame builds only the one BLAS and rebuilds only
/// the one piece it must), every progressive frame of a camera at rest stays within them, its
/// open pixels on the counted fallback, and the camera still converges to the full build's
/// image. Settling at rest (the default) lifts the clock: the same caps then converge in
/// fewer frames, and frames before it settles keep them.
#[test]
fn a_frame_clock_builds_one_blas_a_frame_and_a_camera_at_rest_converges() {
    let Some(Fixture { ctx, h, full }) = Fixture::new("stream_frame_clock", field(10, 16, 30))
    else {
        return;
    };
    let opts = ids_opts(backend(&ctx));
    let cam = base_pose().params(SIZE, SIZE);
    let reference = render(&ctx, &full, &cam, &opts).expect("full render");
    let caps = crate::FrameCaps {
        blases: 1,
        pieces: 1,
        probe: false,
    };
    let run = |o: StreamOptions| {
        let o = StreamOptions {
            budget_bytes: full_build_needs(&full) / 2,
            fallback: crate::StreamFallback::Coarse,
            ..o
        };
        let mut sr = streamer(&ctx, &h, &o);
        let (mut frames, mut last) = (Vec::new(), None);
        for _ in 0..400 {
            let (out, st) = refine(&mut sr, true, &cam, &opts);
            let done = st.complete;
            frames.push(st);
            last = Some(out);
            if done {
                break;
            }
        }
        (frames, last.expect("a frame"))
    };
    let counted = StreamOptions {
        frame_caps: Some(caps),
        settle_after_still_frames: 0,
        ..Default::default()
    };
    let timed = StreamOptions {
        frame_ms: 1e-3,
        settle_after_still_frames: 0,
        ..Default::default()
    };
    let settling = StreamOptions {
        frame_caps: Some(caps),
        ..Default::default()
    };
    let mut lengths = Vec::new();
    for (what, o) in [
        ("counted", counted),
        ("timed", timed),
        ("settling", settling),
    ] {
        let (frames, out) = run(o);
        let first = &frames[0];
        let st = frames.last().expect("a frame");
        eprintln!(
            "{what}: {} frames, {} BLASes, {} stale pieces rebuilt; first frame {} fallback px",
            frames.len(),
            frames.iter().map(|f| f.blas_built).sum::<u32>(),
            frames.iter().map(|f| f.tlas_stale_rebuilt).sum::<u32>(),
            first.fallback_pixels,
        );
        assert!(
            st.complete && st.fallback_pixels == 0 && st.tlas_pieces_stale == 0,
            "{what}: never converged: {st:?}"
        );
        assert_same_aov(&reference.aov, &out.aov, what);
        assert!(
            !first.complete && first.fallback_pixels > 0,
            "{what}: {first:?}"
        );
        // Frames on the clock: one pass, at most one BLAS and one stale piece, every open
        // pixel on the fallback; with settling, only the frames before the camera settles.
        let clocked = if what == "settling" {
            frames.len().min(2)
        } else {
            frames.len()
        };
        for f in &frames[..clocked] {
            assert_eq!(f.passes, 1, "{what}: {f:?}");
            assert!(f.blas_built <= 1, "{what}: {f:?}");
            assert!(f.tlas_stale_rebuilt <= 1, "{what}: {f:?}");
            assert_eq!(f.fallback_pixels, f.incomplete_pixels, "{what}: {f:?}");
        }
        lengths.push(frames.len());
    }
    // A frame at rest builds one BLAS a frame: as many frames as BLASes the view needs.
    assert!(lengths[0] > 8, "{lengths:?}");
    // Settling took the frames after the second past the caps.
    assert!(lengths[2] < lengths[0], "{lengths:?}");
    assert_no_validation_errors(&ctx);
}

/// notes/flight.md D6: on the clock, a complete frame probes the next camera only when a
/// probe round fits: with counts as `FrameCaps::probe` says, and never on a clock out of time
/// (a microsecond), those skipped counted (`probe_skipped_clock`); off the clock it probes as
/// before. A probe on the clock takes `StreamOptions::clocked_probe`'s settings: by default
/// every 4th pixel of each axis (a sixteenth), one round, no verifying round, whatever
/// `probe_stride`, `probe_rounds` and `probe_verify_rounds` say; settings given for it win.
#[test]
fn a_complete_frame_on_the_clock_probes_only_when_a_round_fits() {
    let Some(Fixture { ctx, h, full }) = Fixture::new("stream_clock_probe", field(4, 6, 12)) else {
        return;
    };
    let opts = ids_opts(backend(&ctx));
    let cam = camera_path(&base_pose(), &SWEEP, 0, 4).params(SIZE, SIZE);
    let moved = camera_path(&base_pose(), &SWEEP, 2, 4).params(SIZE, SIZE);
    let reference = render(&ctx, &full, &cam, &opts).expect("full render");
    // The first complete progressive frame at `cam` with `moved` named next.
    let first_complete = |o: StreamOptions| {
        let o = StreamOptions {
            frame_ms: o.frame_ms,
            frame_caps: o.frame_caps,
            probe_rounds: o.probe_rounds,
            probe_verify_rounds: o.probe_verify_rounds,
            clocked_probe: o.clocked_probe,
            settle_after_still_frames: 0,
            ..small_stream_options(full_build_needs(&full) * 2)
        };
        let mut sr = streamer(&ctx, &h, &o);
        for _ in 0..200 {
            sr.set_next_camera(Some(moved));
            let (out, st) = sr.render_progressive(&cam, &opts).expect("frame");
            if st.complete {
                assert_same_aov(&reference.aov, &out.aov, "a complete frame");
                return st;
            }
        }
        panic!("never complete");
    };
    let caps = |probe| StreamOptions {
        frame_caps: Some(crate::FrameCaps {
            blases: 1000,
            pieces: 1000,
            probe,
        }),
        ..Default::default()
    };
    // Full probes everywhere they are not replaced: every pixel, rounds and verifying rounds.
    let full_probe = |o: StreamOptions| StreamOptions {
        probe_rounds: 3,
        probe_verify_rounds: 2,
        ..o
    };
    let off = first_complete(full_probe(StreamOptions::default()));
    let allowed = first_complete(full_probe(caps(true)));
    let refused = first_complete(caps(false));
    let timed = first_complete(StreamOptions {
        frame_ms: 1e-3,
        ..Default::default()
    });
    // Given settings win: a whole probe of one round on the clock.
    let given = first_complete(StreamOptions {
        clocked_probe: Some(crate::ProbeSettings {
            stride: 1,
            rounds: 1,
            verify_rounds: 0,
        }),
        ..caps(true)
    });
    for (what, st, probed) in [
        ("off the clock", &off, true),
        ("caps with the probe", &allowed, true),
        ("caps without it", &refused, false),
        ("out of time", &timed, false),
        ("caps with given settings", &given, true),
    ] {
        assert!(!st.probe_skipped_still, "{what}: {st:?}");
        assert_eq!(st.probe_rays > 0, probed, "{what}: {st:?}");
        // Complete, with a next camera and a stride: only the clock skips the probe.
        assert_eq!(st.probe_skipped_clock, u32::from(!probed), "{what}: {st:?}");
    }
    // View::Ids: one probe ray a probed pixel. On the clock a sixteenth of the pixels in one
    // round; off it every pixel in the first round alone.
    let pixels = u64::from(SIZE * SIZE);
    eprintln!(
        "probe rays: off the clock {} in {} rounds ({} verifying), on it {} in {} ({}), \
         given settings {}",
        off.probe_rays,
        off.probe_rounds,
        off.probe_verify_rounds,
        allowed.probe_rays,
        allowed.probe_rounds,
        allowed.probe_verify_rounds,
        given.probe_rays
    );
    assert!(off.probe_rays >= pixels, "{off:?}");
    assert!(allowed.probe_rays <= pixels.div_ceil(16), "{allowed:?}");
    assert_eq!(
        (allowed.probe_rounds, allowed.probe_verify_rounds),
        (1, 0),
        "{allowed:?}"
    );
    assert_eq!(given.probe_rays, pixels, "{given:?}");
    assert_no_validation_errors(&ctx);
}

/// The clock's estimates steer nothing off the clock: a renderer whose estimates say every
/// build, piece and tail takes hours renders a frame build budget's frames (bytes; progressive
/// and whole frames) with the same per-frame counts as a fresh one.
#[test]
fn frames_off_the_clock_ignore_its_estimates() {
    let Some(Fixture { ctx, h, full }) = Fixture::new("stream_off_clock", field(10, 16, 30)) else {
        return;
    };
    let opts = ids_opts(backend(&ctx));
    let cam = base_pose().params(SIZE, SIZE);
    let counts = |progressive: bool, poisoned: bool| {
        let mut sr = streamer(&ctx, &h, &refining_options(&full));
        if poisoned {
            let clock = sr.frame.kept_mut().clock_mut();
            let t0 = std::time::Instant::now();
            clock.note_build(3.6e6, 1);
            clock.note_pieces(3.6e6, 1);
            clock.note_probe(3.6e6);
            clock.begin(t0);
            clock.decided(Some(t0));
            clock.end(t0 + std::time::Duration::from_secs(3600));
        }
        let mut v = Vec::new();
        for _ in 0..200 {
            let (_, st) = refine(&mut sr, progressive, &cam, &opts);
            v.push((
                st.passes,
                st.blas_built,
                st.build_groups,
                st.tlas_rebuilt,
                st.fallback_pixels,
                st.complete,
            ));
            if st.complete {
                break;
            }
        }
        v
    };
    for progressive in [false, true] {
        let fresh = counts(progressive, false);
        // (passes, blas_built, build_groups, tlas_rebuilt, fallback_pixels, complete) a
        // frame: main's (8026589) are the same (notes/clock51.md).
        eprintln!("off the clock, progressive {progressive}: {fresh:?}");
        assert!(fresh.len() > 2, "refined over several frames: {fresh:?}");
        assert_eq!(
            fresh,
            counts(progressive, true),
            "progressive {progressive}"
        );
    }
    assert_no_validation_errors(&ctx);
}

/// notes/flight.md D5A: on the clock, a progressive frame whose next camera is another builds
/// only into free room. Along the sweep at a sixteenth of the full build, where the same frames
/// off the clock evict, no moving frame evicts; some stop their build queue at the free room
/// (`flying_no_room`, what they left on the counted fallback); the camera at rest evicts again
/// as it must and converges to the full build's image. (At a quarter and an eighth the clock's
/// frames, which build fewer BLASes than those off it, never filled the room along 12 frames.)
#[test]
fn flying_frames_on_the_clock_evict_nothing_and_a_camera_at_rest_converges() {
    let Some(Fixture { ctx, h, full }) = Fixture::new("stream_flying", field(10, 16, 30)) else {
        return;
    };
    let opts = ids_opts(backend(&ctx));
    // Frames 0..MOVING-1 name the next pose of the sweep; from MOVING-1 on the camera rests.
    const MOVING: u32 = 12;
    let rest = sweep_then_rest(MOVING, MOVING);
    let reference = render(&ctx, &full, &rest, &opts).expect("full render");
    let run = |frame_caps: Option<crate::FrameCaps>| {
        let o = StreamOptions {
            fallback: crate::StreamFallback::Coarse,
            frame_caps,
            ..small_stream_options(full_build_needs(&full) / 16)
        };
        let mut sr = streamer(&ctx, &h, &o);
        let (mut frames, mut last) = (Vec::new(), None);
        for f in 0..MOVING + 40 {
            sr.set_next_camera(Some(sweep_then_rest(f + 1, MOVING)));
            let (out, st) = sr
                .render_progressive(&sweep_then_rest(f, MOVING), &opts)
                .expect("frame");
            let done = f >= MOVING && st.complete;
            frames.push(st);
            last = Some(out);
            if done {
                break;
            }
        }
        (frames, last.expect("a frame"))
    };
    let moving = (MOVING - 1) as usize;
    let counts = |frames: &[FrameStreamStats]| -> Vec<(u32, u32, u32, u64, bool)> {
        frames
            .iter()
            .map(|f| {
                (
                    f.passes,
                    f.blas_built,
                    f.evicted,
                    f.fallback_pixels,
                    f.complete,
                )
            })
            .collect()
    };
    // Off the clock: the budget makes moving frames evict (main's counts, notes/flight52.md).
    let (off, off_out) = run(None);
    eprintln!(
        "off the clock (passes, blas_built, evicted, fallback_pixels, complete): {:?}",
        counts(&off)
    );
    assert!(off[..moving].iter().any(|f| f.evicted > 0), "{off:?}");
    assert!(off.iter().all(|f| f.flying_no_room == 0), "{off:?}");
    assert_same_aov(&reference.aov, &off_out.aov, "off the clock at rest");
    // On the clock with counts for times, every BLAS the frame wants (within the free room
    // while flying) and the probe.
    let caps = crate::FrameCaps {
        blases: 1000,
        pieces: 1000,
        probe: true,
    };
    let (on, out) = run(Some(caps));
    eprintln!(
        "on the clock (passes, blas_built, evicted, fallback_pixels, complete): {:?}, no room \
         {:?}",
        counts(&on),
        on.iter().map(|f| f.flying_no_room).collect::<Vec<_>>()
    );
    for f in &on[..moving] {
        assert_eq!(f.evicted, 0, "a moving frame evicted: {f:?}");
        assert_eq!(f.passes, 1, "{f:?}");
        assert_eq!(f.fallback_pixels, f.incomplete_pixels, "{f:?}");
    }
    assert!(
        on[..moving].iter().any(|f| f.flying_no_room > 0),
        "no moving frame ran out of free room: {on:?}"
    );
    assert!(on[moving..].iter().all(|f| f.flying_no_room == 0), "{on:?}");
    let st = on.last().expect("a frame");
    assert!(
        st.complete && st.fallback_pixels == 0,
        "never converged: {st:?}"
    );
    assert_same_aov(&reference.aov, &out.aov, "on the clock at rest");
    assert_no_validation_errors(&ctx);
}

/// Issue 45 items 5 and 6: a refining frame (its build budget spent after its first pass)
/// traces again, in its last pass, only the open pixels whose structures could have arrived:
/// a pixel whose primary ray waits for a structure still not built is left as it is (its
/// fallback stays, counted). Its last pass traces no secondary rays ahead of an open primary
/// ray (progressive frames: their one pass is the last). The counts are the shaders' own, and
/// both modes still converge to the full build's image at rest.
#[test]
fn a_refining_frames_last_pass_traces_only_pixels_whose_structures_arrived() {
    let Some(Fixture { ctx, h, full }) = Fixture::new("stream_refine", field(10, 16, 30)) else {
        return;
    };
    let shading = motu_abi::shade::Shading {
        spp: 1,
        ..full_shading()
    };
    // Secondary rays a pixel whose primary ray is final may trace in one pass (spp 1, no
    // bounce): its lights' shadow rays and its AO rays, each once.
    let per_pixel = u64::from(shading.light_count + shading.ao_samples);
    let opts = RenderOptions {
        shading,
        ..ids_opts(backend(&ctx))
    };
    let cam = base_pose().params(SIZE, SIZE);
    let reference = render(&ctx, &full, &cam, &opts).expect("full render");
    for progressive in [false, true] {
        let mut sr = streamer(&ctx, &h, &refining_options(&full));
        let (mut left_waiting, mut marked_walks) = (0u64, 0u64);
        let mut last: Option<(RenderOutput, FrameStreamStats)> = None;
        let mut refining_frames = 0u32;
        for _ in 0..200 {
            let (out, st) = refine(&mut sr, progressive, &cam, &opts);
            assert_eq!(st.passes as usize, st.pass_log.len(), "{st:?}");
            if last.as_ref().is_some_and(|(_, prev)| !prev.complete) {
                // A refining frame (the last one left pixels open): its first pass takes no
                // mark walk and no guard ray, and traces no secondary ray ahead of an open
                // primary ray (their work was lost when the pixel waits past the build step).
                let p = &st.pass_log[0];
                assert_eq!((p.mark_walks, st.guard_rays), (0, 0), "{st:?}");
                assert!(
                    p.secondary_rays <= per_pixel * (p.traced - p.open_closest),
                    "{p:?}"
                );
                refining_frames += 1;
            }
            let final_pass = st.pass_log.last().expect("a pass");
            assert!(final_pass.tlas_walks > 0, "{st:?}");
            if !st.complete {
                assert!(final_pass.last_pass, "{st:?}");
                assert_eq!(st.fallback_pixels, st.incomplete_pixels, "{st:?}");
            }
            for (i, p) in st.pass_log.iter().enumerate() {
                marked_walks += p.mark_walks;
                assert!(p.open_closest <= p.open_pixels, "{p:?}");
                if let Some(next) = st.pass_log.get(i + 1) {
                    // The next pass traces the open pixels less those left waiting.
                    assert_eq!(next.traced + p.left_waiting, p.open_pixels, "{st:?}");
                    left_waiting += p.left_waiting;
                    if p.left_waiting > 0 {
                        assert!(next.last_pass, "only a last pass leaves pixels: {st:?}");
                    }
                }
                if p.last_pass {
                    // No secondary rays ahead of open primary (or bounce) rays: only the pixels
                    // it traced whose closest-hit ray ended trace any (those left waiting
                    // before it count in its open_closest but were not traced).
                    let (image, waited) = match i {
                        0 => (p.traced - st.guard_rays, 0),
                        _ => (p.traced, st.pass_log[i - 1].left_waiting),
                    };
                    let still_open = p.open_closest - waited;
                    assert!(
                        p.secondary_rays <= per_pixel * (image - still_open),
                        "{p:?}"
                    );
                }
            }
            let done = st.complete;
            last = Some((out, st));
            if done {
                break;
            }
        }
        eprintln!(
            "progressive {progressive}: left waiting {left_waiting}, mark walks {marked_walks}"
        );
        if !progressive {
            assert!(left_waiting > 0, "no pixel was left waiting");
        }
        assert!(marked_walks > 0);
        assert!(refining_frames > 0, "no refining frame");
        let (out, st) = last.expect("a frame");
        assert!(
            st.complete && st.fallback_pixels == 0,
            "never converged: {st:?}"
        );
        assert_same_aov(&reference.aov, &out.aov, "refined at rest");
        assert_shaded_equal(&reference.rgba8, &out.rgba8, "refined at rest");
    }
    assert_no_validation_errors(&ctx);
}

/// `count` distinct sphere meshes, each its own BLAS placed by a root instance (so the full
/// build has no PI at all); `place(k)` gives sphere k's colour, UV-sphere resolution and
/// instance transform.
fn root_spheres(count: u32, place: impl Fn(u32) -> ([f32; 3], u32, [f32; 12])) -> OwnedHierarchy {
    let mut b = HierarchyBuilder::new();
    let mut root = Vec::new();
    for k in 0..count {
        let (rgb, segments, transform) = place(k);
        let mat = b.material(rgb);
        let m = b.mesh(k, 0, mat, uv_sphere(segments));
        let blas = b.triangle_blas(&[m]);
        root.push((transform, blas));
    }
    let root_tlas = b.tlas(&root);
    b.finish(root_tlas)
}

/// Sixteen spheres of radius 10 around the camera, their centres spread behind it: the camera
/// is inside every one's box, and each is the nearest surface for some pixels.
fn shells_around_the_camera() -> OwnedHierarchy {
    let eye = base_pose().world_eye;
    root_spheres(16, |k| {
        let (a, c) = ((k % 4) as f32 - 1.5, (k / 4) as f32 - 1.5);
        let centre = [eye.x + 1.5 * a, eye.y + 1.5 * c, eye.z + 3.0];
        (
            [0.2 + 0.05 * k as f32, 0.5, 0.4],
            40 + k % 4,
            srt(10.0, 0.0, centre),
        )
    })
}

/// Regression (issue 14, the ⅛ island's one wrong pixel): a ray that starts inside more
/// proxy boxes than a walk's candidate list holds records them all at t_near = 0. The list
/// kept the first PI_CAPACITY and re-walked "beyond the farthest kept" (t_near > 0), so the
/// rest were never seen; under a tight budget the boxes kept were BLASes walked in earlier
/// passes, the pixel found nothing open and finished on a farther surface, exit 0. Candidates
/// are now ordered by (t_near, PI index), so ties are re-walked, never dropped.
#[test]
fn rays_starting_inside_more_boxes_than_a_candidate_list_holds_match_the_full_build() {
    let Some(Fixture { ctx, h, full }) =
        Fixture::new("stream_ties_at_t_zero", shells_around_the_camera())
    else {
        return;
    };
    // A twelfth: a few shells resident at a time, the rest evicted after their pass (before
    // the fix, 156 of 576 pixels differed here on lavapipe with the frame complete).
    let budget = full_build_needs(&full) / 12;
    let cam = base_pose().params(24, 24);
    let backends = available_backends(&ctx);
    for be in backends {
        let opts = ids_view_opts(be);
        let reference = render(&ctx, &full, &cam, &opts).expect("full render");
        let meshes: std::collections::BTreeSet<u32> =
            reference.aov.records.iter().map(|r| r.mesh).collect();
        assert!(
            meshes.len() >= 4 && !meshes.contains(&MISS),
            "each shell is the nearest for some pixels: {meshes:?}"
        );
        let mut sr = streamer(&ctx, &h, &device_meshes(budget));
        let (out, st) = sr.render_frame(&cam, &opts).expect("stream frame");
        eprintln!("{be:?}: {st:?}");
        assert!(st.complete, "{st:?}");
        assert!(st.evicted > 0, "shells walked earlier are evicted: {st:?}");
        assert_same_aov(&reference.aov, &out.aov, &format!("{be:?} ({st:?})"));
    }
    assert_no_validation_errors(&ctx);
}

/// `count` spheres on the view axis, one behind the other, each subtending a wider angle than
/// the one in front (rings around the nearest), so a ray near the axis crosses every proxy box.
fn receding_spheres(count: u32) -> OwnedHierarchy {
    let pose = base_pose();
    let (eye, forward) = (pose.world_eye, pose.world_forward.normalize());
    root_spheres(count, |k| {
        // Distance and angular radius (radians) of sphere k: the last fills most of the view.
        let distance = 2.0 + k as f32;
        let angle = 0.02 + 0.3 * k as f32 / count as f32;
        let centre = eye + forward * distance;
        (
            [0.2 + 0.02 * k as f32, 0.5, 0.8 - 0.02 * k as f32],
            12 + k % 4,
            srt(distance * angle.sin(), 0.0, centre.into()),
        )
    })
}

/// Issue 14, the non-resident path: proxy boxes (non-resident BLASes) are handled during the
/// hardware walk (candidates.glsl `record_proxy`) and never take a candidate slot. Before, a
/// ray crossing N proxy boxes re-walked its TLAS ⌈N / PI_CAPACITY⌉ times per pass (61 walks
/// per ray at ⅛ of the 0.3 island on the H200). Device-independent count: with no PI in the
/// scene, a streamed pixel walks the root TLAS exactly once per pass it is traced in, so the
/// frame's traces equal the pixels traced over its passes (guard probes write no record).
#[test]
fn rays_crossing_many_proxy_boxes_walk_their_tlas_once_per_pass() {
    let count = 40u32;
    let Some(Fixture { ctx, h, full }) =
        Fixture::new("stream_proxy_walks", receding_spheres(count))
    else {
        return;
    };
    let budget = full_build_needs(&full) / 3;
    let cam = base_pose().params(24, 24);
    for be in available_backends(&ctx) {
        let opts = ids_view_opts(be);
        let reference = render(&ctx, &full, &cam, &opts).expect("full render");
        let meshes: std::collections::BTreeSet<u32> =
            reference.aov.records.iter().map(|r| r.mesh).collect();
        assert!(meshes.len() >= 6, "rings of many spheres show: {meshes:?}");
        let mut sr = streamer(&ctx, &h, &small_stream_options(budget));
        let (out, st) = sr.render_frame(&cam, &opts).expect("stream frame");
        eprintln!("{be:?}: {st:?}");
        assert!(st.complete, "{st:?}");
        let traced: u64 = st.pass_log.iter().map(|p| p.traced).sum::<u64>() - st.guard_rays;
        let traces: u64 = out.aov.records.iter().map(|r| u64::from(r.traces)).sum();
        // The centre pixel crosses all `count` proxy boxes in pass 1 (nothing is resident):
        // ⌈count / 8⌉ = 5 walks there alone before.
        let centre = out.aov.records[(12 * 24 + 12) as usize].traces;
        assert!(
            u32::from(centre) <= st.passes,
            "{be:?}: the centre pixel walked {centre} times in {} passes",
            st.passes
        );
        assert_eq!(
            traces, traced,
            "{be:?}: {traces} TLAS walks for {traced} pixels traced over {} passes",
            st.passes
        );
        assert_eq!(out.stats.pi_list_overflows, 0, "{be:?}");
        assert_same_aov(&reference.aov, &out.aov, &format!("{be:?} ({st:?})"));
    }
    assert_no_validation_errors(&ctx);
}

/// A grid of `side`² small spheres at the root, instancing `kinds` BLASes in turn (each a
/// different sphere): one TLAS with many instances of few structures.
fn instanced_grid(side: u32, kinds: u32) -> OwnedHierarchy {
    let mut b = HierarchyBuilder::new();
    let blases: Vec<u32> = (0..kinds)
        .map(|k| {
            let mat = b.material([0.2 + 0.1 * k as f32, 0.6, 0.9 - 0.1 * k as f32]);
            let m = b.mesh(k, 0, mat, uv_sphere(60 + 8 * k));
            b.triangle_blas(&[m])
        })
        .collect();
    let half = (side - 1) as f32 / 2.0;
    let root: Vec<_> = (0..side * side)
        .map(|i| {
            let (x, y) = ((i % side) as f32 - half, (i / side) as f32 - half);
            let z = -0.3 * ((i * 7) % 5) as f32;
            let spacing = 5.0 / side as f32;
            (
                srt(0.4 * spacing, 0.0, [x * spacing, y * spacing, z]),
                blases[(i % kinds) as usize],
            )
        })
        .collect();
    let root_tlas = b.tlas(&root);
    b.finish(root_tlas)
}

/// Issue 45 item 5: a ray that enters a proxy box tests its members' boxes quantised to a byte
/// an axis (`member_boxes.rs`, read contiguously) and reads a member's instance record for the
/// exact test only where it enters the quantised box. The query backend counts both
/// (device-independent counts); the pipeline backend's any-hit cannot and counts none. Either
/// way the frame equals the full build.
#[test]
fn member_tests_read_an_instance_record_only_where_the_quantised_box_is_entered() {
    let Some(Fixture { ctx, h, full }) = Fixture::new("stream_member_tests", instanced_grid(50, 7))
    else {
        return;
    };
    let cam = base_pose().params(32, 32);
    let budget = full_build_needs(&full) / 8;
    let backends = available_backends(&ctx);
    if !backends.contains(&Backend::Query) {
        eprintln!(
            "stream_member_tests: NOT COUNTED: this device has no ray queries, and only the \
             query backend counts member tests"
        );
    }
    for be in backends {
        let opts = ids_view_opts(be);
        let reference = render(&ctx, &full, &cam, &opts).expect("full render");
        let mut sr = streamer(&ctx, &h, &small_stream_options(budget));
        let (out, st) = sr.render_frame(&cam, &opts).expect("stream frame");
        assert!(st.complete, "{st:?}");
        assert_same_aov(&reference.aov, &out.aov, &format!("{be:?} ({st:?})"));
        let tested: u64 = st.pass_log.iter().map(|p| p.proxy_member_tests).sum();
        let exact: u64 = st.pass_log.iter().map(|p| p.proxy_exact_tests).sum();
        eprintln!("{be:?}: {tested} member boxes tested, {exact} exact tests");
        if be == Backend::Pipeline {
            assert_eq!((tested, exact), (0, 0), "the pipeline backend counts none");
            continue;
        }
        // Rays cross clusters of up to 16 spheres and enter few of them: most member tests
        // end at the quantised box, and those that pass it are the exact tests.
        assert!(
            exact > 0 && tested > 4 * exact,
            "{tested} tested, {exact} exact"
        );
    }
    assert_no_validation_errors(&ctx);
}

/// The TLAS instance records are counted, then encoded in place in the staging ring a window
/// of whole chunks at a time (`stream/tlas_records.rs`). With the smallest ring (1,024 records
/// a chunk and a window) a root of 2,500 instances spans three chunks, and with only some of
/// its BLASes resident each window holds several partly resident chunks: the streamed frame
/// still equals the full build, pixel by pixel.
#[test]
fn tlas_records_written_through_a_small_ring_in_windows_match_the_full_build() {
    let h = instanced_grid(50, 7);
    assert_eq!(
        h.view().tlases[h.view().root_tlas as usize].instance_count,
        2_500
    );
    let Some(Fixture { ctx, h, full }) = Fixture::new("stream_tlas_record_windows", h) else {
        return;
    };
    let cam = base_pose().params(32, 32);
    let opts = ids_view_opts(backend(&ctx));
    let reference = render(&ctx, &full, &cam, &opts).expect("full render");
    let kinds: std::collections::BTreeSet<u32> =
        reference.aov.records.iter().map(|r| r.mesh).collect();
    assert!(kinds.len() >= 7, "every kind of sphere shows: {kinds:?}");
    let budget = full_build_needs(&full) / 8;
    // Written by the host (chunks in ring windows), and compacted on the GPU from the kept
    // records (`tlas_compact.rs`: chunks of 1,024, the host writing only the tails).
    for mode in [crate::TlasRecordsMode::Host, crate::TlasRecordsMode::Gpu] {
        let mut sr = streamer(
            &ctx,
            &h,
            &StreamOptions {
                staging_bytes: 64 << 10, // the ring's least size
                tlas_records: mode,
                ..small_stream_options(budget)
            },
        );
        let (out, st) = sr.render_frame(&cam, &opts).expect("stream frame");
        eprintln!("{mode:?}: {st:?}");
        assert!(st.complete, "{st:?}");
        // Partly resident rebuilds happened: a TLAS build wrote fewer records than the root
        // has (plus its proxy and marks) at least once.
        let written = st.tlas_instances_written + st.tlas_records_compacted;
        assert!(
            st.tlas_builds >= 2 && written < u64::from(st.tlas_builds) * 2_502,
            "{st:?}"
        );
        if mode == crate::TlasRecordsMode::Gpu {
            // Each rebuild compacted on the GPU (the host writing its tail: a proxy and a
            // marks record at most) or, at this eighth, written from the host where a refusal
            // with nothing else to evict released the kept records this frame.
            assert!(
                st.tlas_records_compacted > 0 || st.tlas_records_host_fallbacks > 0,
                "{st:?}"
            );
            if st.tlas_records_host_fallbacks == 0 {
                assert!(
                    st.tlas_instances_written <= 2 * u64::from(st.tlas_builds),
                    "{st:?}"
                );
                assert!(st.tlas_records_kept_bytes >= 2_500 * 64, "{st:?}");
            }
        } else {
            assert_eq!(st.tlas_records_compacted, 0, "{st:?}");
        }
        assert_same_aov(&reference.aov, &out.aov, &format!("{mode:?}: {st:?}"));
    }
    assert_no_validation_errors(&ctx);
}

/// A rebuild of TLASes whose clusters' residency did not change (a BLAS under them moved, or
/// was evicted and built back) keeps their proxy and marks BLASes: none is built, the next
/// frame equals the full build. TLASes built for fast build (`--stream-tlas-build`) too.
#[test]
fn rebuilds_keep_unchanged_proxies_and_fast_build_tlases_match_the_full_build() {
    let Some(Fixture { ctx, h, full }) =
        Fixture::new("stream_tlas_proxies_kept", instanced_grid(50, 7))
    else {
        return;
    };
    let cam = base_pose().params(32, 32);
    let opts = ids_view_opts(backend(&ctx));
    let reference = render(&ctx, &full, &cam, &opts).expect("full render");
    let budget = full_build_needs(&full) / 8;
    for tlas_build in [motu_vk::TlasBuild::FastTrace, motu_vk::TlasBuild::FastBuild] {
        let mut sr = streamer(
            &ctx,
            &h,
            &StreamOptions {
                tlas_build,
                ..small_stream_options(budget)
            },
        );
        let (out, st) = sr.render_frame(&cam, &opts).expect("stream frame");
        assert!(st.complete, "{st:?}");
        assert!(st.tlas_proxies_built > 0 && st.tlas_gpu_ms > 0.0, "{st:?}");
        assert_same_aov(&reference.aov, &out.aov, &format!("{tlas_build:?}: {st:?}"));
        // Every resident TLAS dirty with nothing changed: rebuilt, its pair kept.
        let with_clusters = (0..h.view().tlases.len() as u32)
            .filter(|&t| sr.tlases.get(t).is_some() && !sr.topo.clusters(t as usize).is_empty())
            .collect::<Vec<_>>();
        assert!(!with_clusters.is_empty());
        for &t in &with_clusters {
            sr.tlases.instances_changed(t);
        }
        let phases = |st: &crate::FrameStreamStats| {
            st.tlas_gpu_ms
                + st.tlas_upload_ms
                + st.tlas_proxy_ms
                + st.tlas_swap_ms
                + st.tlas_room_ms
                + st.tlas_encode_ms
        };
        let before = (
            sr.frame.stats().tlas_proxies_built,
            sr.frame.stats().tlas_proxies_kept,
            sr.frame.stats().tlas_builds,
        );
        let (phases_before, tlas_ms_before) = (phases(sr.frame.stats()), sr.frame.stats().tlas_ms);
        sr.rebuild_dirty().expect("rebuild");
        let st = sr.frame.stats();
        // The phases are parts of `tlas_ms`.
        let (phases_ms, tlas_ms) = (phases(st) - phases_before, st.tlas_ms - tlas_ms_before);
        assert!(
            phases_ms > 0.0 && phases_ms <= tlas_ms * 1.001 + 0.01,
            "{phases_ms} of {tlas_ms}"
        );
        assert_eq!(st.tlas_proxies_built, before.0, "none built: {st:?}");
        assert!(
            st.tlas_proxies_kept >= before.1 + with_clusters.len() as u32,
            "{before:?} {st:?}"
        );
        assert!(st.tlas_builds > before.2, "{st:?}");
        let (out, st) = sr.render_frame(&cam, &opts).expect("frame at rest");
        assert!(st.complete, "{st:?}");
        assert_same_aov(
            &reference.aov,
            &out.aov,
            &format!("{tlas_build:?} kept: {st:?}"),
        );
    }
    assert_no_validation_errors(&ctx);
}

/// Persistent TLASes (`StreamOptions::tlas_update`, `stream/persistent.rs`): the root is built
/// once over all its 2,500 instances (non-resident ones on placeholders under mask 0) and
/// updated in place as BLASes come and go. Under an eighth of the full build (evictions within
/// a frame) and along a short path, every frame equals the full build pixel by pixel on both
/// backends; updates rewrite only the records of BLASes whose residency changed; `Auto` keeps
/// small scenes rebuilt.
#[test]
fn persistent_tlases_updated_in_place_match_the_full_build_on_both_backends() {
    let Some(Fixture { ctx, h, full }) =
        Fixture::new("stream_persistent_tlas", instanced_grid(50, 7))
    else {
        return;
    };
    let budget = full_build_needs(&full) / 8;
    let path = CameraPath {
        yaw_sweep_deg: 40.0,
        dolly_world: 2.0,
    };
    let frames = 4;
    for be in available_backends(&ctx) {
        let opts = ids_opts(be);
        let mut sr = streamer(
            &ctx,
            &h,
            &StreamOptions {
                tlas_update: crate::TlasUpdate::Update,
                ..small_stream_options(budget)
            },
        );
        let totals = sr.totals();
        assert_eq!(totals.tlas_mode, "update", "{totals:?}");
        assert_eq!(totals.persistent_tlases, 1, "{totals:?}");
        // `motu report`'s estimate (by the same size queries; records aside, which count
        // only where host memory does) is what the renderer keeps, to a placeholder's
        // alignment and build flags.
        let est = crate::persistent_tlas_estimate(&h.view(), &ctx, ctx.limits().max_instance_count)
            .expect("estimate")
            .expect("the driver sizes updatable TLASes");
        assert_eq!((est.tlases, est.instances), (1, 2500), "{est:?}");
        assert_eq!(
            est.auto_min_budget_bytes, None,
            "2,500 instances stay rebuilt"
        );
        let records = if sr.host_visible_counts_against_budget() {
            64 * (est.instances + 2)
        } else {
            0
        };
        let kept = totals.persistent_tlas_bytes - records;
        assert!(
            kept.abs_diff(est.bytes) * 50 <= est.bytes,
            "renderer keeps {kept} bytes besides records, estimate {}",
            est.bytes
        );
        let (mut updates, mut written) = (0, 0);
        for f in 0..frames {
            let cam = camera_path(&base_pose(), &path, f, frames).params(32, 32);
            let (out, st) = sr.render_frame(&cam, &opts).expect("stream frame");
            eprintln!("{be:?} frame {f}: {st:?}");
            assert!(st.complete, "{st:?}");
            assert!(st.vram_peak_bytes <= budget, "{st:?}");
            // Updates, not rebuilds: each patches the records of the BLASes that came or went
            // plus the proxy and marks (all 2,502 when every BLAS changed).
            assert_eq!(st.tlas_updates, st.tlas_builds, "{st:?}");
            assert!(
                st.tlas_instances_written <= u64::from(st.tlas_updates) * 2_502,
                "{st:?}"
            );
            updates += st.tlas_updates;
            written += st.tlas_instances_written;
            let reference = render(&ctx, &full, &cam, &opts).expect("full render");
            assert_same_aov(
                &reference.aov,
                &out.aov,
                &format!("{be:?} frame {f}: {st:?}"),
            );
        }
        assert!(
            updates >= 2,
            "residency changed and the TLAS followed: {updates}"
        );
        // Some BLASes stayed resident across some update: fewer records than a rebuild of
        // everything each time.
        assert!(
            written < u64::from(updates) * 2_502,
            "{written} records in {updates} updates"
        );
        assert!(!sr.totals().persistent_dropped);
    }
    // `Auto` on a scene of 2,500 instances: rebuilt (a rebuild takes milliseconds there).
    let sr = streamer(&ctx, &h, &small_stream_options(budget));
    assert_eq!(sr.totals().tlas_mode, "rebuild");
    assert_eq!(sr.totals().persistent_tlases, 0);
    drop(sr);
    assert_no_validation_errors(&ctx);
}

/// Forced persistent TLASes at 1.05× the streaming floor (sized for rebuilt TLASes): when a
/// BLAS does not fit next to them the renderer drops them and rebuilds from then on, so the
/// floor's guarantee holds whatever `--stream-tlas` says; the frame equals the full build.
#[test]
fn forced_persistent_tlases_at_the_floor_give_way_and_the_frame_completes() {
    let Some(Fixture { ctx, h, full }) =
        Fixture::new("stream_persistent_floor", instanced_grid(50, 7))
    else {
        return;
    };
    let cam = base_pose().params(32, 32);
    let opts = ids_opts(backend(&ctx));
    let reference = render(&ctx, &full, &cam, &opts).expect("full render");
    let base = small_stream_options(0);
    let floor = crate::streaming_floor(&h.view(), &ctx, 32, 32, base.staging_bytes)
        .expect("floor")
        .min_resident_bytes;
    let budget = floor + floor / 20;
    let mut sr = StreamingRenderer::new(
        &ctx,
        h.view(),
        &h,
        &StreamOptions {
            tlas_update: crate::TlasUpdate::Update,
            ..small_stream_options(budget)
        },
    )
    .expect("streaming renderer at 1.05x the floor");
    let before = sr.totals();
    let (out, st) = sr.render_frame(&cam, &opts).expect("stream frame");
    let after = sr.totals();
    eprintln!(
        "floor {floor} budget {budget}: persistent {} B ({}), dropped {}; {:?}",
        before.persistent_tlas_bytes, before.tlas_mode, after.persistent_dropped, st
    );
    assert!(st.complete, "{st:?}");
    assert!(st.vram_peak_bytes <= budget, "{st:?}");
    assert_same_aov(&reference.aov, &out.aov, &format!("{st:?}"));
    if after.persistent_dropped {
        assert_eq!(after.tlas_mode, "rebuild");
        assert_eq!(after.persistent_tlases, 0);
    }
    assert_no_validation_errors(&ctx);
}

/// Stamps (`4 × stamp + level` in u32 tables, the start stamp in 29 bits of a payload) would
/// wrap after 2^29 passes (~20 days of a viewer): the last stamp below the limit still
/// renders, the pass that would reach the limit is refused naming it, and no frame comes back
/// wrong.
#[test]
fn the_pass_stamp_limit_is_refused_by_name() {
    let Some(ctx) = context_or_skip("stream_stamp_limit", Requirement::RayTracing) else {
        return;
    };
    let h = field(2, 2, 4);
    let opts = ids_opts(backend(&ctx));
    let mut sr = streamer(&ctx, &h, &small_stream_options(64 << 20));
    let cam = base_pose().params(SIZE, SIZE);
    let (_, st) = sr
        .render_frame(&cam, &opts)
        .expect("a frame below the limit");
    assert!(st.complete, "{st:?}");
    // The last stamp the payload holds is 2^29 - 1: a one-pass frame still takes it.
    sr.skip_stamps_to((1 << 29) - 2);
    let (_, st) = sr.render_frame(&cam, &opts).expect("the last stamp");
    assert_eq!(st.passes, 1, "{st:?}");
    match sr.render_frame(&cam, &opts) {
        Err(crate::GpuError::LimitExceeded { what, limit, .. }) => {
            assert!(what.contains("stamps"), "{what}");
            assert_eq!(limit, (1 << 29) - 1);
        }
        other => panic!(
            "expected the stamp limit, got {:?}",
            other.map(|(_, st)| st)
        ),
    }
}

/// `PassMarks::Auto` marks after a frame that evicted for build room and skipped no prefetch.
#[test]
fn auto_pass_marks_mark_after_build_room_evictions_with_nothing_skipped() {
    use crate::{PassMarks, AUTO_PASS_FRAMES, AUTO_PASS_ROWS};
    assert_eq!(PassMarks::Off.rows(true), 0);
    assert_eq!(PassMarks::Rows(3).rows(false), 3);
    assert_eq!(PassMarks::Auto.rows(true), AUTO_PASS_ROWS);
    assert_eq!(PassMarks::Auto.rows(false), 0);
    // A third of island 0.3 (evicts for room, skips nothing): on; half (no build-room
    // evictions) and a quarter (skips builds): off.
    assert!(PassMarks::auto_wanted(137, 0));
    assert!(!PassMarks::auto_wanted(0, 0));
    assert!(!PassMarks::auto_wanted(370, 387));
    // Held after frame 3: the probes after frames 4 to 3 + AUTO_PASS_FRAMES mark.
    assert!(!PassMarks::auto_window(5, 0), "never held");
    assert!(PassMarks::auto_window(4, 3));
    assert!(PassMarks::auto_window(3 + AUTO_PASS_FRAMES, 3));
    assert!(!PassMarks::auto_window(4 + AUTO_PASS_FRAMES, 3));
}

/// Draining blocks (`defrag.rs`): after a camera path under a quarter of the full build, with
/// every other BLAS evicted so the blocks are part-used, the streamed BLASes, meshes and
/// textures of the emptiest ones move into other blocks' free space, whole blocks are freed, and the next frame (moved
/// BLASes' parents rebuilt, moved meshes' and textures' addresses rewritten) is the full
/// build's, hits and shaded colours (textured).
#[test]
fn drained_blocks_free_budget_and_the_next_frame_is_unchanged() {
    let Some(Fixture { ctx, h, full }) = Fixture::new(
        "stream_defrag",
        per_material_textures(textured_field(10, 16, 30)),
    ) else {
        return;
    };
    let budget = full_build_needs(&full) / 4;
    let shaded = textured_opts(backend(&ctx));
    let mut sr = streamer(&ctx, &h, &device_meshes(budget));
    let path = SWEEP;
    let frames = 4;
    let mut cam = base_pose().params(32, 32);
    for f in 0..frames {
        cam = camera_path(&base_pose(), &path, f, frames).params(32, 32);
        let (_, st) = sr.render_frame(&cam, &shaded).expect("frame");
        assert!(st.complete, "{st:?}");
    }
    // The path leaves the blocks nearly packed: little or nothing fits elsewhere. Once every
    // other BLAS is evicted, the blocks have ranges that do.
    let packed = sr.defragment_now(false).expect("drain");
    let before = sr.alloc_report();
    let drained = sr.defragment_now(true).expect("drain");
    eprintln!("packed: {packed:?}; thinned: {drained:?}");
    let (moved, freed) = (
        drained.blases + drained.meshes + drained.textures,
        drained.freed_bytes,
    );
    let before_in_use = before.budget_in_use_bytes;
    let after = sr.alloc_report();
    eprintln!(
        "moved {moved}, freed {freed} B: blocks {} -> {} B, in use {} -> {} B",
        before.budget_block_bytes,
        after.budget_block_bytes,
        before.budget_in_use_bytes,
        after.budget_in_use_bytes
    );
    assert!(
        moved > 0 && freed > 0,
        "part-used blocks were drained: {drained:?}"
    );
    assert!(
        drained.blases > 0 && drained.meshes > 0 && drained.textures > 0,
        "structures, meshes and textures move: {drained:?}"
    );
    assert!(before.budget_block_bytes - after.budget_block_bytes >= freed);
    assert!(
        after.budget_in_use_bytes < before_in_use,
        "the thinning evicted"
    );
    let (out, st) = sr
        .render_frame(&cam, &shaded)
        .expect("frame after the drain");
    assert!(st.complete, "{st:?}");
    assert!(st.vram_peak_bytes <= budget, "{st:?}");
    let reference = render(&ctx, &full, &cam, &shaded).expect("full render");
    let cmp = motu_trace::compare(&reference.aov, &out.aov, 0.0).expect("sizes");
    assert_eq!(
        cmp.mismatched, 0,
        "hits equal the full build's after the drain"
    );
    assert_shaded_equal(&reference.rgba8, &out.rgba8, "after the drain");
    drop(sr);
    assert_no_validation_errors(&ctx);
}

/// A camera at rest (the next frame's camera is this frame's) whose frame left resident all it
/// saw skips the probe of the next camera: it could only meet what the frame had resident. A moved camera
/// is probed, and the frames at rest still equal the full build.
#[test]
fn a_camera_at_rest_skips_the_next_camera_probe() {
    let Some(Fixture { ctx, h, full }) = Fixture::new("stream_probe_at_rest", field(4, 6, 12))
    else {
        return;
    };
    let opts = ids_opts(backend(&ctx));
    let budget = full_build_needs(&full) * 2;
    let mut sr = streamer(&ctx, &h, &small_stream_options(budget));
    let cam = camera_path(&base_pose(), &SWEEP, 0, 4).params(SIZE, SIZE);
    let moved = camera_path(&base_pose(), &SWEEP, 2, 4).params(SIZE, SIZE);
    let mut stats = Vec::new();
    for next in [cam, cam, moved] {
        sr.set_next_camera(Some(next));
        let (out, st) = sr.render_frame(&cam, &opts).expect("frame");
        let reference = render(&ctx, &full, &cam, &opts).expect("full render");
        assert_same_aov(&reference.aov, &out.aov, "a frame at rest");
        stats.push(st);
    }
    // The cold first frame builds between passes; the budget evicts nothing it saw, so the
    // probe of the same camera is skipped there too. Once everything is resident the camera at
    // rest takes one pass and skips its probe; the moved camera is probed.
    let cold = &stats[0];
    assert!(cold.passes > 1 && cold.evicted == 0, "{cold:?}");
    assert!(cold.probe_skipped_still, "{cold:?}");
    assert_eq!(cold.probe_rays, 0, "{cold:?}");
    let at_rest = &stats[1];
    assert_eq!(at_rest.passes, 1, "{at_rest:?}");
    assert!(at_rest.probe_skipped_still, "{at_rest:?}");
    assert_eq!(at_rest.probe_rays, 0, "{at_rest:?}");
    let probed = &stats[2];
    assert!(!probed.probe_skipped_still, "{probed:?}");
    assert!(probed.probe_rays > 0, "{probed:?}");
    assert_no_validation_errors(&ctx);
}

/// Issue 47: `--bounces` paths under streaming. Each bounce ray is a closest-hit ray carried
/// across passes like the primary (its best hit resolved while its BLAS is resident, traced
/// again while an open structure lies in front of it), then its vertex's shadow and AO rays in
/// windows. A cold renderer at a sixteenth of the full build (several passes, evicting
/// mid-frame; textures streaming with the meshes bounce rays hit) gives the full build's AOV
/// and colours on both backends with 1 bounce, and with 2 on the first; the bounce is real (0
/// and 1 bounces give different images).
#[test]
fn streamed_bounces_match_the_full_build_on_both_backends() {
    let t0 = std::time::Instant::now();
    let h = textured(field_with_ground(10, 16, 30, true));
    let Some(Fixture { ctx, h, full }) = Fixture::new("stream_bounces", h) else {
        return;
    };
    let cam = base_pose().params(24, 24);
    let budget = full_build_needs(&full) / 16;
    for (k, be) in available_backends(&ctx).into_iter().enumerate() {
        let opts = |bounces| RenderOptions {
            shading: motu_abi::shade::Shading {
                ao_samples: 1,
                spp: 1,
                bounces,
                ..full_shading()
            },
            ..ids_opts(be)
        };
        let direct = render(&ctx, &full, &cam, &opts(0)).expect("full, no bounce");
        let bounce_counts: &[u32] = if k == 0 { &[1, 2] } else { &[1] };
        for &bounces in bounce_counts {
            let what = format!("{be:?}, {bounces} bounces");
            let reference = render(&ctx, &full, &cam, &opts(bounces)).expect("full render");
            let lit = direct
                .rgba8
                .chunks_exact(4)
                .zip(reference.rgba8.chunks_exact(4))
                .filter(|(a, b)| a != b)
                .count();
            assert!(
                lit > 24 * 24 / 10,
                "{what}: the bounce changes {lit} pixels only"
            );
            let mut cold = streamer(&ctx, &h, &no_guard_band(budget));
            let (out, st) = cold.render_frame(&cam, &opts(bounces)).expect("frame");
            eprintln!(
                "{what}: {lit} pixels lit by the bounce; streamed in {} passes, {} evicted, {} \
                 secondary rays ({:.1} s in)",
                st.passes,
                st.evicted,
                out.stats.shadow_rays,
                t0.elapsed().as_secs_f64()
            );
            assert!(st.complete && st.passes >= 2, "{what}: {st:?}");
            assert!(st.evicted > 0, "{what}: evicting mid-frame: {st:?}");
            assert!(st.vram_peak_bytes <= budget, "{what}: {st:?}");
            let cmp = motu_trace::compare(&reference.aov, &out.aov, 0.0).expect("sizes");
            assert_eq!(cmp.mismatched, 0, "{what}: the AOV equals the full build's");
            assert_shaded_equal(&reference.rgba8, &out.rgba8, &what);
        }
    }
    assert_no_validation_errors(&ctx);
}

/// Rebuilt TLASes and their proxy and marks BLASes built without compaction
/// (`StreamOptions::tlas_compact` off, `--stream-tlas-compact off`): no compaction copy, and
/// the frames along a path under an eighth of the full build (evictions mid-frame) match the
/// full build as compacted ones do. Either way every TLAS rebuild is counted by when it ran
/// (before the first pass, between passes, in the prefetch), and no TLAS is rebuilt twice
/// with no trace between: per frame, a TLAS is rebuilt at most once a build step.
#[test]
fn uncompacted_rebuilt_tlases_match_the_full_build_and_rebuild_once_a_step() {
    let Some(Fixture { ctx, h, full }) = Fixture::new("stream_tlas_compact", field(10, 16, 30))
    else {
        return;
    };
    let budget = full_build_needs(&full) / 8;
    let opts = ids_opts(backend(&ctx));
    let tlases = h.view().tlases.len() as u32;
    let frames = 5;
    for tlas_compact in [true, false] {
        let mut sr = streamer(
            &ctx,
            &h,
            &StreamOptions {
                tlas_compact,
                ..small_stream_options(budget)
            },
        );
        let (mut mismatched, mut total) = (0u64, 0u64);
        let mut rebuilt_by_when = 0u32;
        for f in 0..=frames {
            let cam = sweep_then_rest(f, frames);
            let (out, st) = sr.render_frame(&cam, &opts).expect("frame");
            let what = format!("compact {tlas_compact}, frame {f}: {st:?}");
            assert!(st.complete, "{what}");
            assert!(st.tlas_rebuilt > 0 || f > 0, "{what}");
            let by_when =
                st.tlas_rebuilt_at_start + st.tlas_rebuilt_in_passes + st.tlas_rebuilt_in_prefetch;
            // Every rebuild that swapped a TLAS in, of those attempted.
            assert!(by_when <= st.tlas_builds, "{what}");
            rebuilt_by_when += by_when;
            assert_eq!(st.tlas_rebuilt_again, 0, "{what}");
            // Once a step at most: before the first pass, after each pass but the last, and
            // in each prefetch step.
            assert!(st.tlas_rebuilt_at_start <= tlases, "{what}");
            assert!(
                st.tlas_rebuilt_in_passes <= tlases * st.passes.saturating_sub(1),
                "{what}"
            );
            if !tlas_compact {
                assert_eq!(st.tlas_compactions, 0, "{what}");
                assert_eq!(st.tlas_compact_saved_bytes, 0, "{what}");
                assert_eq!(st.tlas_compact_resident_saved_bytes, 0, "{what}");
            }
            assert!(
                st.tlas_compact_saved_bytes >= st.tlas_compactions as u64,
                "{what}"
            );
            if f >= frames - 1 {
                let reference = render(&ctx, &full, &cam, &opts).expect("full render");
                if f == frames {
                    assert_same_aov(&reference.aov, &out.aov, &what);
                }
                let cmp =
                    motu_trace::compare(&reference.aov, &out.aov, motu_trace::DEFAULT_REL_EPS)
                        .expect("sizes");
                mismatched += cmp.mismatched;
                total += cmp.total;
            }
        }
        assert!(
            mismatched as f64 <= 0.001 * total as f64,
            "{mismatched} of {total}"
        );
        assert!(rebuilt_by_when > 0);
        assert_eq!(sr.totals().tlas_compact, tlas_compact);
        assert_eq!(sr.totals().tlas_rebuilt_again, 0);
    }
    assert_no_validation_errors(&ctx);
}

/// A TLAS rebuild group's proxies and TLASes go in one submission (`tlas_build/one_submit.rs`):
/// along a path under an eighth of the full build, the rebuilds submit at most twice a group
/// (once, plus a ring flush when the records outgrow the staging ring), fewer than the
/// sequential path (compaction on: boxes' flush, proxies' batch, records' flush, TLASes'
/// batch), and the frames equal the full build. Without compaction some rebuilt TLASes are
/// built into the storage of the structure they replace (`tlas_build/storage.rs`), none with.
#[test]
fn a_rebuild_group_submits_its_proxies_and_tlases_once() {
    let Some(Fixture { ctx, h, full }) =
        Fixture::new("stream_tlas_one_submission", field(10, 16, 30))
    else {
        return;
    };
    let budget = full_build_needs(&full) / 8;
    let opts = ids_opts(backend(&ctx));
    let frames = 4;
    let mut submits = Vec::new();
    for tlas_compact in [false, true] {
        let mut one_submission = 0u32;
        let (mut reused, mut allocated, mut builds) = (0u32, 0u32, 0u32);
        let mut sr = streamer(
            &ctx,
            &h,
            &StreamOptions {
                tlas_compact,
                ..small_stream_options(budget)
            },
        );
        for f in 0..=frames {
            let cam = sweep_then_rest(f, frames);
            let (out, st) = sr.render_frame(&cam, &opts).expect("frame");
            let what = format!("compact {tlas_compact}, frame {f}: {st:?}");
            assert!(st.complete, "{what}");
            assert!(st.tlas_submits <= st.submits, "{what}");
            assert!(st.tlas_fence_waits <= st.fence_waits, "{what}");
            assert!(st.fence_waits <= st.submits, "{what}");
            one_submission += st.tlas_one_submission;
            reused += st.tlas_storage_reused;
            allocated += st.tlas_storage_allocated;
            builds += st.tlas_builds;
            assert!(
                st.tlas_storage_reused + st.tlas_storage_allocated <= st.tlas_builds,
                "{what}"
            );
            if tlas_compact {
                assert_eq!(st.tlas_one_submission, 0, "{what}");
            } else {
                assert!(
                    st.tlas_submits <= 2 * u64::from(st.tlas_rebuild_groups),
                    "{what}"
                );
            }
            if f == frames {
                let reference = render(&ctx, &full, &cam, &opts).expect("full render");
                assert_same_aov(&reference.aov, &out.aov, &what);
            }
        }
        let t = sr.totals();
        eprintln!(
            "compact {tlas_compact}: {} TLAS submits, {} waits, {} groups, {} submits",
            t.tlas_submits, t.tlas_fence_waits, t.tlas_rebuild_groups, t.submits
        );
        assert!(t.tlas_rebuild_groups > 0 && t.tlas_submits > 0, "{t:?}");
        assert_eq!(one_submission > 0, !tlas_compact, "{t:?}");
        eprintln!("compact {tlas_compact}: storage reused {reused}, allocated {allocated}, {builds} builds");
        assert_eq!(reused > 0, !tlas_compact, "{t:?}");
        assert_eq!(u64::from(reused), t.tlas_storage_reused);
        assert_eq!(u64::from(allocated), t.tlas_storage_allocated);
        submits.push((t.tlas_submits, t.tlas_rebuild_groups));
    }
    let (one, seq) = (submits[0], submits[1]);
    // Per group: at most 2 in one submission; at least 2 (proxies kept) sequentially.
    assert!(one.0 * seq.1 < seq.0 * one.1, "{one:?} against {seq:?}");
    assert_no_validation_errors(&ctx);
}

/// Evictions for a TLAS rebuild's room spare clean TLASes (`victims_sparing_clean_tlases`):
/// with one row's TLAS dirty and the least recently seen BLAS under another, making room for
/// less than that row holds evicts only under it (no clean TLAS becomes dirty: none would be
/// rebuilt again in the step), and room for more than it holds dirties one more TLAS, not one
/// per victim; the next frame rebuilds them and equals the full build.
#[test]
fn evictions_for_tlas_room_spare_clean_tlases_and_the_frame_matches_the_full_build() {
    use super::residency::EvictWhy;
    let Some(Fixture { ctx, h, full }) =
        Fixture::new("stream_tlas_room_victims", field(10, 16, 30))
    else {
        return;
    };
    let opts = ids_opts(backend(&ctx));
    let cam = camera_path(&base_pose(), &SWEEP, 0, 1).params(SIZE, SIZE);
    // Room for everything: the frame leaves every BLAS it met resident.
    let budget = 4 * full_build_needs(&full);
    let mut sr = streamer(&ctx, &h, &small_stream_options(budget));
    let (_, st) = sr.render_frame(&cam, &opts).expect("frame");
    assert!(st.complete && !sr.tlases.any_dirty(), "{st:?}");
    sr.res.unpin_all(sr.item_count());
    let lru = sr.lru_victims(1);
    let first = lru.first().expect("a resident BLAS").0 as usize;
    // Resident BLASes (and their bytes) per row TLAS that is not the first victim's parent.
    let mut under = std::collections::BTreeMap::<u32, Vec<u64>>::new();
    for id in sr.lru_victims(u64::MAX) {
        let b = id.0 as usize;
        let parents = sr.topo.parents(b);
        if parents.len() == 1 && !sr.topo.parents(first).contains(&parents[0]) {
            under
                .entry(parents[0])
                .or_default()
                .push(sr.res.blas_bytes(b));
        }
    }
    let (&row, bytes) = under
        .iter()
        .max_by_key(|(_, v)| v.len())
        .expect("a row with resident BLASes");
    assert!(bytes.len() >= 3, "{under:?}");
    let row_bytes: u64 = bytes.iter().sum();
    sr.tlases.instances_changed(row);
    // Least recently seen first would take `first` and dirty its row.
    let (before, before_bytes) = (sr.frame.stats().evicted, sr.frame.stats().evicted_bytes);
    assert!(sr.evict_some(bytes[0], EvictWhy::TlasRoom).expect("evict"));
    let dirty: Vec<u32> = sr.tlases.dirty().iter().copied().collect();
    assert_eq!(dirty, [row], "victims under the dirty row only");
    assert!(sr.res.holds(first as u32));
    assert!(sr.frame.stats().evicted > before);
    // A byte more than the row still holds: its BLASes, then one of one more TLAS.
    let left = row_bytes - (sr.frame.stats().evicted_bytes - before_bytes);
    assert!(sr.evict_some(left + 1, EvictWhy::TlasRoom).expect("evict"));
    assert_eq!(sr.tlases.dirty().len(), 2, "{:?}", sr.tlases.dirty());
    assert!(sr.tlases.dirty().contains(&row));
    // The next frame rebuilds the two before its first trace.
    let (out, st) = sr
        .render_frame(&cam, &opts)
        .expect("frame after the evictions");
    assert!(st.complete && st.tlas_rebuilt >= 2, "{st:?}");
    let reference = render(&ctx, &full, &cam, &opts).expect("full render");
    assert_same_aov(&reference.aov, &out.aov, "after evictions for TLAS room");
    assert_no_validation_errors(&ctx);
}

#[test]
fn a_pass_launch_folds_its_items_into_image_rows() {
    use super::buffers::launch_dims;
    assert_eq!(launch_dims(640 * 360, 640), [640, 360]);
    assert_eq!(launch_dims(640 * 360 + 100, 640), [640, 361]);
    assert_eq!(launch_dims(37, 640), [37, 1]);
    assert_eq!(launch_dims(0, 640), [1, 1]);
    // Wider than the widest row: folded at 4096.
    assert_eq!(launch_dims(10_000, 8192), [4096, 3]);
    assert_eq!(launch_dims(5, 0), [1, 5]);
}

/// Issue 45.6 (notes/flight.md D4): with a frame build budget in milliseconds, a TLAS dirty
/// only because BLASes under it were built (stale) is traced as it is and rebuilt while the
/// budget holds (`piece_order.rs`). The field's rows are TLASes of their own; room for
/// everything, so nothing is evicted and only builds dirty them. A budget of a microsecond:
/// each progressive frame builds one group (a frame that built nothing yet builds one), and
/// rebuilds stale TLASes only in a frame that built no BLAS. Against the same frames with
/// every dirty TLAS rebuilt at each step's end (`defer_stale_tlases: false`, main's rule):
/// frames leave stale TLASes and are then not complete, pixels wait on them (on the
/// fallback, counted), frames that build rebuild no TLAS (main's rebuild some), and the
/// camera at rest still converges to the full build's image.
#[test]
fn stale_tlases_wait_for_the_frame_build_budget_and_a_camera_at_rest_converges() {
    let Some(Fixture { ctx, h, full }) = Fixture::new("stream_stale_tlases", field(10, 16, 30))
    else {
        return;
    };
    let opts = ids_opts(backend(&ctx));
    let cam = base_pose().params(SIZE, SIZE);
    let reference = render(&ctx, &full, &cam, &opts).expect("full render");
    let run = |defer: bool| {
        let o = StreamOptions {
            budget_bytes: 4 * full_build_needs(&full),
            fallback: crate::StreamFallback::Coarse,
            frame_build_ms: 1e-3,
            defer_stale_tlases: defer,
            settle_after_still_frames: 0,
            ..Default::default()
        };
        let mut sr = streamer(&ctx, &h, &o);
        let (mut frames, mut last) = (Vec::new(), None);
        for _ in 0..300 {
            let (out, st) = refine(&mut sr, true, &cam, &opts);
            let done = st.complete;
            frames.push(st);
            last = Some(out);
            if done {
                break;
            }
        }
        (frames, last.expect("a frame"))
    };
    let (main, main_out) = run(false);
    let (stale, stale_out) = run(true);
    let sum =
        |v: &[FrameStreamStats], f: fn(&FrameStreamStats) -> u32| v.iter().map(f).sum::<u32>();
    eprintln!(
        "rebuilt at once: {} frames, {} TLAS rebuilds; stale: {} frames, {} TLAS rebuilds \
         ({} of stale ones), most stale {}, most pixels behind them {}",
        main.len(),
        sum(&main, |f| f.tlas_rebuilt),
        stale.len(),
        sum(&stale, |f| f.tlas_rebuilt),
        sum(&stale, |f| f.tlas_stale_rebuilt),
        stale.iter().map(|f| f.tlas_pieces_stale).max().unwrap_or(0),
        stale
            .iter()
            .map(|f| f.stale_blocked_pixels)
            .max()
            .unwrap_or(0),
    );
    for (what, frames, out) in [
        ("rebuilt at once", &main, &main_out),
        ("stale", &stale, &stale_out),
    ] {
        let st = frames.last().expect("a frame");
        assert!(
            st.complete && st.tlas_pieces_stale == 0 && st.fallback_pixels == 0,
            "{what}: never converged: {st:?}"
        );
        assert_same_aov(&reference.aov, &out.aov, what);
        assert!(frames.iter().all(|f| f.evicted == 0), "{what}: evicted");
    }
    // Every dirty TLAS rebuilt at each step's end: never a stale one.
    for f in &main {
        assert_eq!(
            (
                f.tlas_pieces_stale,
                f.stale_blocked_pixels,
                f.tlas_stale_rebuilt
            ),
            (0, 0, 0),
            "{f:?}"
        );
    }
    assert!(
        stale.iter().any(|f| f.tlas_pieces_stale > 0 && !f.complete),
        "no frame left a stale TLAS"
    );
    assert!(
        stale.iter().any(|f| f.stale_blocked_pixels > 0),
        "no pixel waited for a stale TLAS"
    );
    for f in &stale {
        assert!(f.tlas_pieces_stale == 0 || !f.complete, "{f:?}");
        assert!(f.stale_blocked_pixels <= f.fallback_pixels, "{f:?}");
        assert!(f.tlas_stale_rebuilt <= f.tlas_rebuilt, "{f:?}");
        if f.blas_built > 0 {
            // The budget went to the BLASes: nothing evicted, so no TLAS had to be rebuilt.
            assert_eq!(f.tlas_rebuilt, 0, "{f:?}");
        }
    }
    // Main's rule rebuilds in the frames that build; here each BLAS has one parent row, so
    // the run's total is about the same (16 and 16 on lavapipe), but it takes more frames at
    // rest (13 → 25): a frame that builds leaves its rows for a later frame. The island's
    // pieces share BLASes: `tests/tests/stream_stale_tlases.rs` compares totals there.
    assert!(
        main.iter().any(|f| f.blas_built > 0 && f.tlas_rebuilt > 0),
        "main's rule rebuilt no TLAS in a frame that built"
    );
    assert_no_validation_errors(&ctx);
}
