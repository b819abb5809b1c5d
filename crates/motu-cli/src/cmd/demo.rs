//! `motu demo`: the README's main job on the embedded default scene — generate, import, render
//! with the best available backend — printing where time and memory went.

use crate::cli::{BackendArg, DemoArgs, GenArgs, GenKindArg, RenderArgs, ViewArg};
use crate::pipeline::{self, ImportOptions};
use crate::size::format_size;
use anyhow::Context;
use std::time::Instant;

pub use motu_import::peak_rss_bytes;

fn step(name: &str, t: Instant) {
    let rss = peak_rss_bytes()
        .map(format_size)
        .unwrap_or_else(|| "?".into());
    println!(
        "  {name:<34} {:>9.1} ms   peak RSS {rss}",
        t.elapsed().as_secs_f64() * 1e3
    );
}

pub fn run(a: DemoArgs) -> anyhow::Result<()> {
    std::fs::create_dir_all(&a.work_dir)
        .with_context(|| format!("creating {}", a.work_dir.display()))?;
    let scene_dir = a.work_dir.join("forest");
    let pkg = a.work_dir.join("forest.motu");
    println!(
        "motu demo: a nested-instancing forest (trees of instanced leaves, instanced in groups)"
    );

    let t = Instant::now();
    let gen = GenArgs {
        kind: GenKindArg::Forest,
        output: scene_dir.clone(),
        force: true,
        levels: None,
        grid: None,
        leaves: None,
        trunk_segments: None,
        depth: None,
        sphere_segments: None,
        scale: None,
        elements: None,
        triangles: None,
        spacing: None,
        flat: false,
        seed: None,
        width: Some(640),
        height: Some(360),
        threads: None,
        max_mesh_triangles: None,
        terrain_objects: false,
        format: crate::cli::GenFormatArg::Pbrt,
        json: false,
    };
    let kind = super::gen::options(&gen)?;
    // The demo's own scene directory is replaced whole on each run (`motu gen --force`).
    let out = crate::output::OutputDir::begin("--work-dir", &scene_dir, true)?;
    let mut summary =
        motu_gen::generate(&kind, out.path(), &mut |_| {}).context("generating the demo scene")?;
    if let Ok(rel) = summary.scene_path.strip_prefix(out.path()) {
        summary.scene_path = scene_dir.join(rel);
    }
    let entry = summary
        .scene_path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    out.commit(&entry)?;
    step(
        &format!("gen forest ({})", format_size(summary.bytes_written)),
        t,
    );

    let t = Instant::now();
    // `motu import`'s defaults.
    let opts = ImportOptions {
        progress: crate::progress::import_bar(),
        ..Default::default()
    };
    let s = pipeline::import(&summary.scene_path, &pkg, &opts)?;
    step(
        &format!("import → {} ({})", pkg.display(), format_size(s.file_bytes)),
        t,
    );
    println!(
        "    {} instance edges → {} flattened instances ({} instanced triangles) in {} TLAS + {} BLAS",
        s.instances, s.flattened_instances, summary.instanced_triangles, s.tlas_count, s.blas_count
    );

    let backend = match motu_gpu::list_devices() {
        Ok(devices) => {
            for d in &devices {
                println!(
                    "    device {}: {} (ray pipeline: {}, ray query: {})",
                    d.index, d.name, d.ray_pipeline, d.ray_query
                );
            }
            crate::cmd::render::best_backend(&devices)
        }
        Err(e) => {
            println!("    no Vulkan device ({e}); rendering on the CPU");
            BackendArg::Cpu
        }
    };

    let t = Instant::now();
    let stats_path = a.work_dir.join("demo-stats.json");
    let args = |backend| RenderArgs {
        package: pkg.clone(),
        output: a.output.clone(),
        camera: None,
        width: Some(320),
        height: None,
        backend: Some(backend),
        view: ViewArg::Shaded,
        aov: Some(a.work_dir.join("demo.aov")),
        vram_budget: None,
        max_allocations: None,
        blas_build: None,
        stream: false,
        allow_incomplete: false,
        stream_max_passes: None,
        stream_always: false,
        stream_bounds: crate::cli::StreamBoundArgs {
            stream_fallback: crate::cli::FallbackArg::Off,
            stream_build_budget: None,
            stream_build_ms: None,
            stream_frame_ms: None,
            stream_probe: None,
            stream_probe_rounds: None,
            stream_probe_verify: None,
            stream_probe_later: None,
            stream_probe_paths: None,
            stream_probe_pass_rows: None,
            stream_tlas: crate::cli::StreamTlasArg::Auto,
            stream_split_instances: None,
            stream_defrag: false,
            stream_prefetch_keeps_frame: false,
            stream_victims_by_frequency: false,
            stream_mesh_memory: crate::cli::MeshMemoryArg::Auto,
            stream_host_cache: crate::cli::HostCacheArg::Auto,
            stream_host_cache_policy: crate::cli::HostCachePolicyArg::Measured,
            stream_rates: crate::cli::StreamRatesArg::default(),
            stream_tlas_records: crate::cli::TlasRecordsArg::Gpu,
            stream_tlas_build: crate::cli::TlasBuildArg::FastTrace,
            stream_tlas_compact: crate::cli::OnOffArg::Off,
            stream_tlas_headroom: None,
        },
        as_cache: crate::cli::AsCacheArgs {
            host_cache: None,
            as_cache: None,
            no_as_cache: false,
        },
        frames: 1,
        stats: Some(stats_path.clone()),
        subset: Vec::new(),
        lod: None,
        lod_r_max: 256.0,
        shadow_lod_bias: 1.0,
        lod_stochastic: false,
        lod_mode: crate::cli::LodModeArg::Instance,
        stack_size: 16,
        max_traces_per_ray: motu_abi::DEFAULT_MAX_TRACES_PER_RAY,
        allow_truncated: false,
        pipeline_stats: false,
        spp: 1,
        ao_samples: 1,
        ao_reach: motu_render::AO_DISTANCE_OF_DIAGONAL,
        exposure: crate::cli::ExposureArg::Auto,
        bounces: motu_render::ShadingOptions::default().bounces,
        denoise: false,
        device: None,
        camera_path: None,
    };
    if let Err(e) = super::render::run(args(backend)) {
        if backend == BackendArg::Cpu {
            return Err(e);
        }
        // The deduplicating printer: a cause a message already shows is not repeated.
        println!(
            "    the GPU backend failed ({}); rendering on the CPU instead",
            crate::error_paragraph(&e)
        );
        super::render::run(args(BackendArg::Cpu))?;
    }
    step(&format!("render {}", a.output.display()), t);
    println!(
        "wrote {} (statistics in {})",
        a.output.display(),
        stats_path.display()
    );
    Ok(())
}
