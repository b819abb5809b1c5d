//! Traversal against brute force, watertightness, multi-level vs flattened, LOD and shading.

use motu_abi::camera::CameraParams;
use motu_abi::lod::{LodParams, LOD_NOT_FORCED, RAY_SHADOW};
use proptest::prelude::*;

use crate::ray::{LocalRay, IDENTITY_3X4};
use crate::render::{render_with, RenderOptions, View};
use crate::testutil::{
    srt, uv_sphere, BruteForce, BruteHit, HierarchyBuilder, OwnedHierarchy, PiTarget,
};
use crate::{compare, Hit, MeshGeometry, RayQuery, Scratch, TraceError, Tracer};

/// xorshift64*: deterministic scenes from a proptest seed.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f32 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        ((self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 40) as f32) / (1u64 << 24) as f32
    }
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.next()
    }
    fn below(&mut self, n: usize) -> usize {
        ((self.next() * n as f32) as usize).min(n - 1)
    }
}

fn soup(rng: &mut Rng, tris: usize) -> MeshGeometry {
    let mut positions = Vec::new();
    for _ in 0..tris * 3 {
        positions.push([
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
        ]);
    }
    MeshGeometry {
        indices: (0..positions.len() as u32).collect(),
        positions,
        normals: None,
        primitive_map: None,
        uvs: None,
    }
}

fn random_xform(rng: &mut Rng, spread: f32) -> [f32; 12] {
    srt(
        rng.range(0.4, 2.0),
        rng.range(0.0, std::f32::consts::TAU),
        [
            rng.range(-spread, spread),
            rng.range(-spread, spread),
            rng.range(-spread, spread),
        ],
    )
}

/// Random instanced soups: one level, or a root whose PIs lead to inner TLASes.
fn random_scene(seed: u64, two_level: bool) -> OwnedHierarchy {
    let mut rng = Rng(seed | 1);
    let mut b = HierarchyBuilder::new();
    let blases: Vec<u32> = (0..3)
        .map(|i| {
            let n = 3 + rng.below(20);
            let m = b.mesh(i, 0, 0, soup(&mut rng, n));
            b.triangle_blas(&[m])
        })
        .collect();
    let instances = |rng: &mut Rng, n: usize, spread: f32| -> Vec<([f32; 12], u32)> {
        (0..n)
            .map(|_| (random_xform(rng, spread), blases[rng.below(blases.len())]))
            .collect()
    };
    let root = if two_level {
        let inner: Vec<u32> = (0..2)
            .map(|_| {
                let inst = {
                    let n = 2 + rng.below(4);
                    instances(&mut rng, n, 2.0)
                };
                b.tlas(&inst)
            })
            .collect();
        let pis: Vec<([f32; 12], PiTarget)> = (0..2 + rng.below(4))
            .map(|_| {
                (
                    random_xform(&mut rng, 4.0),
                    PiTarget::Tlas(inner[rng.below(inner.len())]),
                )
            })
            .collect();
        let pi_blas = b.pi_blas(&pis);
        let mut root = {
            let n = 1 + rng.below(3);
            instances(&mut rng, n, 4.0)
        };
        root.push((random_xform(&mut rng, 1.0), pi_blas));
        b.tlas(&root)
    } else {
        let inst = {
            let n = 1 + rng.below(8);
            instances(&mut rng, n, 4.0)
        };
        b.tlas(&inst)
    };
    b.finish(root)
}

/// Barycentric tolerance of an edge graze (see `check_against_brute_force`).
const EDGE_EPS: f64 = 1e-5;

/// Whether traversal's `got` is the brute force's `want` for a ray from `org`: both miss, or
/// both hit at the same t (f32 error), the same triangle unless at a tie.
fn agrees(got: &Hit, want: Option<BruteHit>, org: [f32; 3]) -> Result<(), String> {
    match want {
        None if got.is_hit() => Err(format!("brute force misses, traversal hit {got:?}")),
        None => Ok(()),
        Some(w) if !got.is_hit() => Err(format!("traversal missed {w:?}")),
        Some(w) => {
            // f32 transforms of an origin ~15 units out: absolute error ~1e-6.
            let err = (got.t as f64 - w.t).abs();
            let scale = org.iter().fold(1.0f32, |m, v| m.max(v.abs())) as f64;
            if err >= 1e-4 * w.t + 1e-5 * scale {
                return Err(format!("t {} vs {}", got.t, w.t));
            }
            // A different triangle only at a tie (shared edge or coincident surfaces).
            if (got.mesh_record, got.primitive) != (w.mesh_record, w.primitive)
                && err >= 1e-5 * (w.t + scale)
            {
                return Err("different triangle at different t".into());
            }
            Ok(())
        }
    }
}

fn check_against_brute_force(h: &OwnedHierarchy, seed: u64) -> Result<(), TestCaseError> {
    let tracer = Tracer::new(h.view(), h).unwrap();
    let brute = BruteForce::new(h, 0);
    let mut rng = Rng(seed.rotate_left(17) | 1);
    let mut scratch = Scratch::default();
    let mut hits = 0;
    for _ in 0..64 {
        let org = [
            rng.range(-15.0, 15.0),
            rng.range(-15.0, 15.0),
            rng.range(-15.0, 15.0),
        ];
        let target = [
            rng.range(-4.0, 4.0),
            rng.range(-4.0, 4.0),
            rng.range(-4.0, 4.0),
        ];
        let dir = [target[0] - org[0], target[1] - org[1], target[2] - org[2]];
        let got = tracer.trace(org, dir, &RayQuery::default(), &mut scratch);
        let want = brute.closest(org, dir, 0.0);
        if want.is_some() {
            hits += 1;
        }
        // f32 traversal (two transforms deep) decides a ray that grazes an edge within
        // f32 rounding either way: its answer must be the f64 brute force's with every
        // triangle exact, grown or shrunk by EDGE_EPS (the grazes seen: ~1e-7).
        if let Err(e) = agrees(&got, want, org) {
            let graze = [EDGE_EPS, -EDGE_EPS]
                .iter()
                .any(|&eps| agrees(&got, brute.closest_within(org, dir, 0.0, eps), org).is_ok());
            prop_assert!(graze, "{}", e);
        }
        prop_assert!(got.traces >= 1);
    }
    prop_assert!(brute.triangle_count() > 0 && hits <= 64);
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    #[test]
    fn one_level_matches_brute_force(seed in any::<u64>()) {
        check_against_brute_force(&random_scene(seed, false), seed)?;
    }

    #[test]
    fn two_levels_match_brute_force(seed in any::<u64>()) {
        check_against_brute_force(&random_scene(seed, true), seed)?;
    }
}

#[test]
fn random_scenes_get_hit() {
    // Guards the property tests against vacuous passes (every ray missing).
    let h = random_scene(7, true);
    let tracer = Tracer::new(h.view(), &h).unwrap();
    let mut s = Scratch::default();
    let hits = (0..200)
        .filter(|i| {
            let f = *i as f32 * 0.05;
            let d = [f.sin() * 0.1, f.cos() * 0.1, -1.0];
            tracer
                .trace([0.0, 0.0, 20.0], d, &RayQuery::default(), &mut s)
                .is_hit()
        })
        .count();
    assert!(hits > 10, "{hits}");
}

#[test]
fn ray_through_shared_vertex_and_edges_of_a_fan_hits_exactly_once() {
    // A fan of 7 triangles around (0.3, 0.2, 0.1) in a tilted plane: no ray through a shared
    // vertex or edge may fall between them.
    let centre = [0.3f32, 0.2, 0.1];
    let n = 7;
    let mut positions = vec![centre];
    for i in 0..n {
        let a = i as f32 / n as f32 * std::f32::consts::TAU;
        positions.push([
            centre[0] + a.cos(),
            centre[1] + a.sin(),
            centre[2] + 0.3 * a.cos(),
        ]);
    }
    let indices: Vec<u32> = (0..n as u32)
        .flat_map(|i| [0, 1 + i, 1 + (i + 1) % n as u32])
        .collect();
    let g = MeshGeometry {
        positions: positions.clone(),
        indices: indices.clone(),
        normals: None,
        primitive_map: None,
        uvs: None,
    };
    let mut b = HierarchyBuilder::new();
    let m = b.mesh(0, 0, 0, g);
    let blas = b.triangle_blas(&[m]);
    let root = b.tlas(&[(IDENTITY_3X4, blas)]);
    let h = b.finish(root);
    let tracer = Tracer::new(h.view(), &h).unwrap();
    let mut s = Scratch::default();
    let mut targets = vec![centre];
    for &p in &positions[1..] {
        // Points along the shared edge centre → p.
        for k in 1..8 {
            let f = k as f32 / 8.0;
            targets.push([
                centre[0] + f * (p[0] - centre[0]),
                centre[1] + f * (p[1] - centre[1]),
                centre[2] + f * (p[2] - centre[2]),
            ]);
        }
    }
    let origins = [
        [0.0, 0.0, 5.0],
        [1.7, -2.3, 3.1],
        [-4.0, 1.0, -2.5],
        [0.31, 0.19, 9.0],
    ];
    for org in origins {
        for t in &targets {
            let dir = [t[0] - org[0], t[1] - org[1], t[2] - org[2]];
            let ray = LocalRay::new(org, crate::ray::normalize(dir));
            let count = indices
                .chunks_exact(3)
                .filter(|tri| {
                    let v = |k: u32| positions[k as usize];
                    ray.hit_triangle(v(tri[0]), v(tri[1]), v(tri[2]), 0.0, f32::INFINITY)
                        .is_some()
                })
                .count();
            assert!(
                count >= 1,
                "ray from {org:?} to {t:?} leaked through the fan"
            );
            let hit = tracer.trace(org, dir, &RayQuery::default(), &mut s);
            assert!(hit.is_hit());
            let want = crate::ray::length(dir);
            assert!((hit.t - want).abs() < 1e-4 * want, "{} vs {want}", hit.t);
        }
    }
}

/// Three levels of programmable instances above instanced spheres, and its flattening.
fn nested_scene() -> (OwnedHierarchy, OwnedHierarchy) {
    let mut b = HierarchyBuilder::new();
    let red = b.material([0.9, 0.2, 0.2]);
    let sphere = b.mesh(0, 0, red, uv_sphere(12));
    let cube_ish = b.mesh(1, 0, 0, uv_sphere(4));
    let leaf_blas = b.triangle_blas(&[sphere]);
    let other_blas = b.triangle_blas(&[cube_ish]);
    let leaf = b.tlas(&[
        (srt(1.0, 0.0, [0.0, 0.0, 0.0]), leaf_blas),
        (srt(0.5, 1.0, [1.2, 0.3, 0.5]), other_blas),
    ]);
    let mid_pis: Vec<_> = (0..3)
        .map(|i| {
            (
                srt(1.0, i as f32, [i as f32 * 2.5 - 2.5, 0.0, 0.0]),
                PiTarget::Tlas(leaf),
            )
        })
        .collect();
    let mid_blas = b.pi_blas(&mid_pis);
    let mid = b.tlas(&[(IDENTITY_3X4, mid_blas)]);
    let top_pis: Vec<_> = (0..3)
        .map(|i| {
            (
                srt(0.8, 0.3 * i as f32, [0.0, i as f32 * 2.0 - 2.0, -i as f32]),
                PiTarget::Tlas(mid),
            )
        })
        .collect();
    let top_blas = b.pi_blas(&top_pis);
    let root = b.tlas(&[
        (IDENTITY_3X4, top_blas),
        (srt(0.4, 0.0, [3.0, 3.0, 0.0]), leaf_blas),
    ]);
    let ml = b.finish(root);

    // Flattened: one TLAS, one instance per leaf placement (f64 composition rounded once).
    let mut f = HierarchyBuilder::new();
    f.material([0.9, 0.2, 0.2]);
    let mut blas_of = Vec::new();
    for (i, g) in ml.geometry.iter().enumerate() {
        let r = &ml.meshes[i];
        let m = f.mesh(r.source_mesh, r.lod, r.material, g.clone());
        blas_of.push(f.triangle_blas(&[m]));
    }
    let inst: Vec<_> = crate::testutil::flatten(&ml.view(), 0)
        .iter()
        .map(|fi| {
            let m: [f32; 12] = std::array::from_fn(|k| fi.world_from_mesh[k / 4][k % 4] as f32);
            (m, blas_of[fi.mesh_record as usize])
        })
        .collect();
    assert_eq!(inst.len(), 3 * 3 * 2 + 1);
    let root = f.tlas(&inst);
    (ml, f.finish(root))
}

fn camera(w: u32, h: u32) -> CameraParams {
    CameraParams::new(
        glam::Vec3::new(0.5, 0.5, 6.0),
        glam::Vec3::new(0.0, 0.0, -1.0),
        glam::Vec3::Y,
        70.0,
        false,
        w,
        h,
    )
}

#[test]
fn multi_level_equals_flattened() {
    let (ml, sl) = nested_scene();
    let opts = RenderOptions {
        view: View::Ids,
        ..Default::default()
    };
    let cam = camera(96, 64);
    let a = render_with(&Tracer::new(ml.view(), &ml).unwrap(), &cam, &opts).unwrap();
    let b = render_with(&Tracer::new(sl.view(), &sl).unwrap(), &cam, &opts).unwrap();
    let hits = a
        .aov
        .records
        .iter()
        .filter(|r| r.mesh != motu_abi::aov::MISS)
        .count();
    assert!(hits > 800, "scene should cover the view: {hits}");
    let r = compare(&a.aov, &b.aov, crate::DEFAULT_REL_EPS).unwrap();
    assert!(
        r.fraction <= 0.002,
        "{} of {} differ",
        r.mismatched,
        r.total
    );
    // Single level: one trace per ray; multi level: more.
    assert_eq!(b.stats.traces, b.stats.rays);
    assert!(a.stats.traces_per_ray > 1.5, "{}", a.stats.traces_per_ray);
    assert!(a.stats.max_stack_depth >= 2);
}

#[test]
fn one_changed_pixel_is_detected_on_a_render() {
    let (ml, _) = nested_scene();
    let out = crate::render(ml.view(), &ml, &camera(32, 32), &RenderOptions::default()).unwrap();
    let mut b = out.aov.clone();
    let i = b
        .records
        .iter()
        .position(|r| r.mesh != motu_abi::aov::MISS)
        .unwrap();
    b.records[i].t *= 1.01;
    let r = compare(&out.aov, &b, crate::DEFAULT_REL_EPS).unwrap();
    assert_eq!(r.mismatched, 1);
    let (x, y) = (i as u32 % 32, i as u32 / 32);
    assert_eq!(r.bbox, Some([x, y, x, y]));
}

/// (distance, angle off -Z in degrees): far enough apart that no sphere hides another.
const LOD_DISTANCES: [(f32, f32); 4] = [(5.0, -20.0), (20.0, -5.0), (80.0, 10.0), (320.0, 25.0)];

fn towards(angle_deg: f32) -> [f32; 3] {
    [angle_deg.to_radians().tan(), 0.0, -1.0]
}

/// Spheres at growing distance, each behind a selector with 4 levels (mesh `lod` = level).
fn lod_scene() -> OwnedHierarchy {
    let mut b = HierarchyBuilder::new();
    let levels: Vec<u32> = (0..4)
        .map(|l| {
            let m = b.mesh(0, l, 0, uv_sphere(24 >> l));
            let blas = b.triangle_blas(&[m]);
            b.tlas(&[(IDENTITY_3X4, blas)])
        })
        .collect();
    let sel = b.lod_selector(&levels, 0);
    let pis: Vec<_> = LOD_DISTANCES
        .iter()
        .map(|&(d, angle)| {
            let x = d * angle.to_radians().tan();
            (srt(1.0, 0.0, [x, 0.0, -d]), PiTarget::LodSelector(sel))
        })
        .collect();
    let blas = b.pi_blas(&pis);
    let root = b.tlas(&[(IDENTITY_3X4, blas)]);
    b.finish(root)
}

#[test]
fn lod_gets_coarser_with_distance_and_can_be_forced() {
    let h = lod_scene();
    let tracer = Tracer::new(h.view(), &h).unwrap();
    let mut s = Scratch::default();
    let lod = LodParams {
        r_max_px: 64.0,
        ..Default::default()
    };
    let cam = camera(256, 256);
    let q = RayQuery {
        lod,
        pixels_per_unit_at_1: cam.pixels_per_unit_at_1,
        ..Default::default()
    };
    let mut levels = Vec::new();
    for (d, angle) in LOD_DISTANCES {
        let hit = tracer.trace([0.0, 0.0, 0.0], towards(angle), &q, &mut s);
        assert!(hit.is_hit(), "sphere at {d}");
        let centre = d / angle.to_radians().cos();
        assert!(
            hit.t > centre - 1.01 && hit.t < centre,
            "t {} at {d}",
            hit.t
        );
        // The reported level is the selector's and matches the hit mesh's.
        assert_eq!(hit.lod, h.meshes[hit.mesh_record as usize].lod);
        assert_eq!(hit.source_mesh, 0);
        levels.push(hit.lod);
    }
    assert!(levels.windows(2).all(|w| w[0] <= w[1]), "{levels:?}");
    assert!(levels[0] < levels[3], "{levels:?}");
    let forced = RayQuery {
        lod: LodParams {
            forced_lod: 2,
            ..lod
        },
        ..q
    };
    let hit = tracer.trace([0.0, 0.0, 0.0], towards(-20.0), &forced, &mut s);
    assert_eq!(hit.lod, 2);
    // Shadow rays are biased coarser than primary rays at the same distance.
    let shadow = RayQuery {
        kind: RAY_SHADOW,
        lod: LodParams {
            forced_lod: LOD_NOT_FORCED,
            shadow_bias: 1.0,
            ..lod
        },
        ..q
    };
    let p = tracer.trace([0.0, 0.0, 0.0], towards(-5.0), &q, &mut s);
    let sh = tracer.trace([0.0, 0.0, 0.0], towards(-5.0), &shadow, &mut s);
    assert_eq!(sh.lod, (p.lod + 1).min(3));
}

/// Instance-level LOD (motu_abi::lod_instance): the selectors of `lod_scene` become instance
/// slots; with the levels the camera rule picks applied, every ray makes one TLAS walk and
/// hits the level `select_lod` gives for the eye's distance to the selector's sphere.
#[test]
fn instance_lod_takes_one_trace_at_the_camera_level() {
    use motu_abi::lod::select_lod;
    use motu_abi::lod_instance::InstanceLod;
    let h = lod_scene();
    let base = h.view();
    let il = InstanceLod::new(&base)
        .unwrap()
        .expect("the root's selectors qualify");
    assert_eq!(il.slots.len(), LOD_DISTANCES.len());
    assert_eq!(il.traversal_selectors, 0);
    let lod = LodParams {
        r_max_px: 64.0,
        ..Default::default()
    };
    let ppu = camera(256, 256).pixels_per_unit_at_1;
    let levels = il.levels(&base, &lod, ppu, [0.0; 3]);
    let mut frame = il.clone();
    frame.apply_levels(&base, &levels);
    let tracer = Tracer::new(frame.view(&base), &h).unwrap();
    let mut s = Scratch::default();
    let q = RayQuery {
        lod,
        pixels_per_unit_at_1: ppu,
        ..Default::default()
    };
    for (k, (d, angle)) in LOD_DISTANCES.into_iter().enumerate() {
        let hit = tracer.trace([0.0, 0.0, 0.0], towards(angle), &q, &mut s);
        assert!(hit.is_hit(), "sphere at {d}");
        assert_eq!(
            hit.traces, 1,
            "sphere at {d}: one walk, no traversal-shader hop"
        );
        let centre = d / angle.to_radians().cos();
        let radius = base.lod_selectors[0].radius;
        let want = select_lod(&lod, ppu, radius, 1.0, centre, 4, 0, 0.0);
        assert_eq!(levels[k], want, "sphere at {d}");
        assert_eq!(hit.lod, want, "sphere at {d}");
    }
    assert!(levels[0] < levels[3], "{levels:?}");

    // A selector in a TLAS placed twice has no single camera distance: traversal path.
    let mut b = HierarchyBuilder::new();
    let lv: Vec<u32> = (0..2)
        .map(|l| {
            let m = b.mesh(0, l, 0, uv_sphere(8 >> l));
            let blas = b.triangle_blas(&[m]);
            b.tlas(&[(IDENTITY_3X4, blas)])
        })
        .collect();
    let sel = b.lod_selector(&lv, 0);
    let inner = b.pi_blas(&[(IDENTITY_3X4, PiTarget::LodSelector(sel))]);
    let child = b.tlas(&[(IDENTITY_3X4, inner)]);
    let twice = b.pi_blas(&[
        (srt(1.0, 0.0, [-2.0, 0.0, -5.0]), PiTarget::Tlas(child)),
        (srt(1.0, 0.0, [2.0, 0.0, -5.0]), PiTarget::Tlas(child)),
    ]);
    let root = b.tlas(&[(IDENTITY_3X4, twice)]);
    let h2 = b.finish(root);
    assert!(InstanceLod::new(&h2.view()).unwrap().is_none());
}

#[test]
fn shadow_ray_darkens_the_ground_under_an_occluder() {
    let mut b = HierarchyBuilder::new();
    let ground = MeshGeometry {
        positions: vec![
            [-10.0, 0.0, -10.0],
            [10.0, 0.0, -10.0],
            [10.0, 0.0, 10.0],
            [-10.0, 0.0, 10.0],
        ],
        indices: vec![0, 1, 2, 0, 2, 3],
        normals: None,
        primitive_map: None,
        uvs: None,
    };
    let g = b.mesh(0, 0, 0, ground);
    let s = b.mesh(1, 0, 0, uv_sphere(16));
    let gb = b.triangle_blas(&[g]);
    let sb = b.triangle_blas(&[s]);
    let root = b.tlas(&[(IDENTITY_3X4, gb), (srt(1.0, 0.0, [0.0, 3.0, 0.0]), sb)]);
    let h = b.finish(root);
    let cam = CameraParams::new(
        glam::Vec3::new(0.0, 20.0, 0.01),
        glam::Vec3::NEG_Y,
        glam::Vec3::Z,
        60.0,
        false,
        33,
        33,
    );
    let opts = RenderOptions {
        sun_dir_world: [0.6, 1.0, 0.0],
        ..Default::default()
    };
    let out = crate::render(h.view(), &h, &cam, &opts).unwrap();
    let px = |x: usize, y: usize| out.rgba8[(y * 33 + x) * 4];
    // Centre: the sphere's top (lit); a ring around it on the ground; the far corner lit.
    let corner = px(1, 1);
    assert!(out.stats.shadow_rays > 0);
    // Directly below the sphere's rim the ground is in shadow: find a ground pixel near the
    // sphere whose shade is darker than the far ground.
    let shadowed = (0..33)
        .flat_map(|y| (0..33).map(move |x| (x, y)))
        .filter(|&(x, y)| out.aov.records[y * 33 + x].mesh == 0 && px(x, y) < corner)
        .count();
    assert!(shadowed > 0, "no shadowed ground pixel");
    assert_eq!(out.aov.records[16 * 33 + 16].mesh, 1);
}

#[test]
fn views_and_stats() {
    let (ml, _) = nested_scene();
    let tracer = Tracer::new(ml.view(), &ml).unwrap();
    let cam = camera(40, 30);
    for view in [View::Shaded, View::Ids, View::Lod, View::Heatmap] {
        let out = render_with(
            &tracer,
            &cam,
            &RenderOptions {
                view,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(out.rgba8.len(), 40 * 30 * 4);
        assert_eq!(out.stats.primary_rays, 1200);
        assert!(out.stats.rays_per_second > 0.0);
        assert!(out.stats.heatmap_max_traces >= 2);
        let max = out.aov.records.iter().map(|r| r.traces).max().unwrap();
        assert_eq!(out.stats.heatmap_max_traces, max as u32);
        if view == View::Heatmap {
            let i = out
                .aov
                .records
                .iter()
                .position(|r| r.traces == max)
                .unwrap();
            assert_eq!(&out.rgba8[i * 4..i * 4 + 3], &[255, 0, 0]);
        }
    }
}

#[test]
fn broken_hierarchies_are_errors() {
    // A cycle: root → PI → root.
    let mut b = HierarchyBuilder::new();
    let m = b.mesh(0, 0, 0, uv_sphere(4));
    let tb = b.triangle_blas(&[m]);
    let t = b.tlas(&[(IDENTITY_3X4, tb)]);
    let pb = b.pi_blas(&[(IDENTITY_3X4, PiTarget::Tlas(t))]);
    let root = b.tlas(&[(IDENTITY_3X4, pb)]);
    let mut h = b.finish(root);
    h.pis[0].target = root;
    assert!(matches!(
        Tracer::new(h.view(), &h),
        Err(TraceError::Cycle { .. })
    ));
    // A mesh whose geometry fails to load: reported, not a panic.
    h.pis[0].target = t;
    h.geometry.clear();
    let err = crate::render(h.view(), &h, &camera(8, 8), &RenderOptions::default()).unwrap_err();
    assert!(matches!(err, TraceError::Mesh { mesh: 0, .. }), "{err}");
    h.instances[0].blas = 99;
    assert!(matches!(
        Tracer::new(h.view(), &h),
        Err(TraceError::Hierarchy(_))
    ));
}

#[test]
fn very_deep_nesting_uses_the_explicit_stack() {
    let mut b = HierarchyBuilder::new();
    let m = b.mesh(0, 0, 0, uv_sphere(8));
    let blas = b.triangle_blas(&[m]);
    let mut tlas = b.tlas(&[(IDENTITY_3X4, blas)]);
    let depth = 300;
    for _ in 0..depth {
        let pb = b.pi_blas(&[(srt(1.0, 0.0, [0.01, 0.0, 0.0]), PiTarget::Tlas(tlas))]);
        tlas = b.tlas(&[(IDENTITY_3X4, pb)]);
    }
    let h = b.finish(tlas);
    let tracer = Tracer::new(h.view(), &h).unwrap();
    let mut s = Scratch::default();
    // The sphere sits at x = 3 after 300 shifts of 0.01.
    let hit = tracer.trace(
        [3.0, 0.0, 10.0],
        [0.0, 0.0, -1.0],
        &RayQuery::default(),
        &mut s,
    );
    assert!(hit.is_hit());
    assert!((hit.t - 9.0).abs() < 0.01, "{}", hit.t);
    assert_eq!(hit.traces, depth + 1);
    let miss = tracer.trace(
        [0.0, 0.0, 10.0],
        [0.0, 0.0, -1.0],
        &RayQuery::default(),
        &mut s,
    );
    assert!(!miss.is_hit());
}

/// A LOD level may bulge outside the finer one (here: level 1 is a 15% larger shell). A shadow
/// ray leaving the level-0 surface that picks its own (biased, coarser) level starts inside
/// that shell and shadows its own surface; forcing the primary hit's level (what the renderer
/// does, `shadow_lod_from_primary`) removes that self-shadowing.
#[test]
fn forced_shadow_lod_removes_lod_self_shadowing() {
    let mut b = HierarchyBuilder::new();
    let fine = b.mesh(0, 0, 0, uv_sphere(32));
    let mut shell = uv_sphere(8);
    for p in &mut shell.positions {
        *p = [p[0] * 1.15, p[1] * 1.15, p[2] * 1.15];
    }
    let coarse = b.mesh(0, 1, 0, shell);
    let levels: Vec<u32> = [fine, coarse]
        .iter()
        .map(|&m| {
            let blas = b.triangle_blas(&[m]);
            b.tlas(&[(IDENTITY_3X4, blas)])
        })
        .collect();
    let sel = b.lod_selector(&levels, 0);
    let blas = b.pi_blas(&[(IDENTITY_3X4, PiTarget::LodSelector(sel))]);
    let root = b.tlas(&[(IDENTITY_3X4, blas)]);
    let h = b.finish(root);
    let tracer = Tracer::new(h.view(), &h).unwrap();
    let mut s = Scratch::default();
    let lod = LodParams {
        r_max_px: 1.0,
        shadow_bias: 1.0,
        ..Default::default()
    };
    let sun = [0.0, 1.0, 0.0];
    let (mut biased_shadowed, mut forced_shadowed, mut samples) = (0, 0, 0);
    for i in 0..64 {
        // Points on the sun-facing cap, reached by primary rays from above.
        let a = i as f32 * 0.37;
        let org = [0.6 * a.cos(), 5.0, 0.6 * a.sin()];
        let primary = RayQuery {
            lod,
            pixels_per_unit_at_1: 500.0,
            ..Default::default()
        };
        let hit = tracer.trace(org, [0.0, -1.0, 0.0], &primary, &mut s);
        assert!(hit.is_hit());
        assert_eq!(hit.lod, 0, "close up, primary rays see the fine level");
        let p = [org[0], org[1] - hit.t, org[2]];
        let n = hit.world_normal();
        let n = if n[1] < 0.0 { [-n[0], -n[1], -n[2]] } else { n };
        let start = crate::render::shadow_offset(p, n, 5.0 + hit.t);
        let shadow = RayQuery {
            kind: RAY_SHADOW,
            any_hit: true,
            lod,
            pixels_per_unit_at_1: 500.0,
            ..Default::default()
        };
        let forced = RayQuery {
            lod: LodParams {
                forced_lod: hit.lod as i32,
                ..lod
            },
            ..shadow
        };
        biased_shadowed += tracer.trace(start, sun, &shadow, &mut s).is_hit() as u32;
        forced_shadowed += tracer.trace(start, sun, &forced, &mut s).is_hit() as u32;
        samples += 1;
    }
    assert!(
        biased_shadowed > samples / 2,
        "the coarse shell shadows the surface: {biased_shadowed}/{samples}"
    );
    assert_eq!(forced_shadowed, 0, "forced LOD: no self-shadowing");
}
