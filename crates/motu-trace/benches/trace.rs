//! CPU traversal throughput (rays/s) on synthetic instanced scenes.
//!
//! `small`: 1,000 instances of a 1,800-triangle sphere, one level and the same placements
//! behind two levels of programmable instances, 128×128 primary rays (ids view).
//! `buddha_like` (set `MOTU_BENCH_LARGE=1`): buddha-fractal's shape — 25,250 instances of a
//! ~29,500-triangle mesh — at 256×410, shaded with one shadow ray per hit.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use glam::Vec3;
use motu_abi::camera::CameraParams;
use motu_trace::ray::IDENTITY_3X4;
use motu_trace::testutil::{srt, uv_sphere, HierarchyBuilder, OwnedHierarchy, PiTarget};
use motu_trace::{render_with, RenderOptions, Tracer, View};

/// `count` spheres on a jittered square grid in the XZ plane; with `two_level`, rows become
/// inner TLASes placed through programmable instances.
fn grid_scene(count: usize, segments: u32, two_level: bool) -> OwnedHierarchy {
    let mut b = HierarchyBuilder::new();
    let m = b.mesh(0, 0, 0, uv_sphere(segments));
    let blas = b.triangle_blas(&[m]);
    let side = (count as f32).sqrt().ceil() as usize;
    let place = |i: usize| {
        let (x, z) = ((i % side) as f32, (i / side) as f32);
        let s = 0.3 + 0.2 * ((i * 7919) % 13) as f32 / 13.0;
        srt(s, i as f32, [x - side as f32 / 2.0, s, -z])
    };
    let root = if two_level {
        let row = b.tlas(
            &(0..side)
                .map(|x| {
                    (
                        srt(0.4, x as f32, [x as f32 - side as f32 / 2.0, 0.4, 0.0]),
                        blas,
                    )
                })
                .collect::<Vec<_>>(),
        );
        let pis: Vec<_> = (0..count.div_ceil(side))
            .map(|z| (srt(1.0, 0.0, [0.0, 0.0, -(z as f32)]), PiTarget::Tlas(row)))
            .collect();
        let pb = b.pi_blas(&pis);
        b.tlas(&[(IDENTITY_3X4, pb)])
    } else {
        b.tlas(&(0..count).map(|i| (place(i), blas)).collect::<Vec<_>>())
    };
    b.finish(root)
}

fn camera(side: f32, w: u32, h: u32) -> CameraParams {
    CameraParams::new(
        Vec3::new(0.0, side * 0.35, side * 0.25),
        Vec3::new(0.0, -0.45, -1.0),
        Vec3::Y,
        50.0,
        false,
        w,
        h,
    )
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("trace");
    g.sample_size(10);
    for (name, two_level) in [("small_1level", false), ("small_2level", true)] {
        let scene = grid_scene(1000, 30, two_level);
        let tracer = Tracer::new(scene.view(), &scene).expect("valid scene");
        let cam = camera(32.0, 128, 128);
        let opts = RenderOptions {
            view: View::Ids,
            ..Default::default()
        };
        tracer.prepare().expect("meshes load");
        g.throughput(Throughput::Elements(128 * 128));
        g.bench_function(name, |b| {
            b.iter(|| render_with(&tracer, &cam, &opts).expect("renders"))
        });
    }
    if std::env::var_os("MOTU_BENCH_LARGE").is_some() {
        let scene = grid_scene(25_250, 122, false);
        let tracer = Tracer::new(scene.view(), &scene).expect("valid scene");
        let cam = camera(160.0, 256, 410);
        let opts = RenderOptions::default();
        let first = render_with(&tracer, &cam, &opts).expect("renders");
        eprintln!(
            "buddha_like: prepare {:.0} ms, {} rays in {:.0} ms = {:.0} rays/s, {:.2} traces/ray",
            first.stats.prepare_ms,
            first.stats.rays,
            first.stats.ms_per_frame,
            first.stats.rays_per_second,
            first.stats.traces_per_ray
        );
        g.throughput(Throughput::Elements(first.stats.rays));
        g.bench_function("buddha_like_256x410_shaded", |b| {
            b.iter(|| render_with(&tracer, &cam, &opts).expect("renders"))
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
