//! `motu import`: pbrt/OBJ → compiled, chunked scene package.

use crate::cli::{ImportArgs, LevelsArg};
use crate::pipeline::{self, ImportOptions};
use crate::size::format_size;
use motu_compile::Levels;

pub fn run(a: ImportArgs) -> anyhow::Result<()> {
    // A FIFO, device or symlink loop as the scene is named before anything opens it (a missing
    // scene is the pipeline's own error, and so is a directory: Moana's base package may be
    // named by its folder, anything else is refused there by name).
    if let motu_package::identity::InputKind::Other(what) =
        motu_package::identity::classify_input(&a.scene)
    {
        if a.scene.is_dir() {
            return import_checked(a);
        }
        anyhow::bail!("scene {}: is {what}, not a regular file", a.scene.display());
    }
    import_checked(a)
}

fn import_checked(a: ImportArgs) -> anyhow::Result<()> {
    crate::output::check_outputs(&[("scene", &a.scene)], &[("-o", &a.output)])?;
    // Before any pool thread exists (issue 48 item 1: peak RSS); A/B switch
    // MOTU_IMPORT_MALLOC_ARENAS=default (glibc's own count) or a count.
    let arenas = match std::env::var("MOTU_IMPORT_MALLOC_ARENAS") {
        Ok(v) if v.trim() == "default" => 0,
        Ok(v) => v.trim().parse().map_err(|e| {
            anyhow::anyhow!("MOTU_IMPORT_MALLOC_ARENAS={v}: not a count or `default` ({e})")
        })?,
        Err(_) => motu_import::IMPORT_MALLOC_ARENAS,
    };
    motu_import::cap_malloc_arenas(arenas);
    if let Some(t) = a.threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(cap_threads("--threads", t)?)
            .build_global()
            .ok();
    }
    if let Some(b) = a.max_tlas_scratch {
        // Build scratch the compiler budgets per TLAS instance.
        let per_instance = motu_compile::CompileOptions::default()
            .scratch_bytes_per_instance
            .max(1);
        if b / per_instance < 2 {
            anyhow::bail!(
                "--max-tlas-scratch {} allows {} instance(s) per TLAS at {per_instance} B of build scratch each; a TLAS split needs at least 2, so give at least {} B",
                crate::size::format_size(b),
                b / per_instance,
                2 * per_instance
            );
        }
    }
    let (levels, levels_text) = match a.levels {
        LevelsArg::Ml => (Levels::Ml, "ml".to_string()),
        LevelsArg::Sl => (Levels::Sl, "sl".to_string()),
        LevelsArg::Auto => (Levels::Auto, "auto".to_string()),
        LevelsArg::N(n) => (Levels::N(n), n.to_string()),
    };
    if a.max_instances < 2 {
        anyhow::bail!(
            "--max-instances {} is too small: a TLAS split needs at least 2",
            a.max_instances
        );
    }
    if let Some(l) = a.zstd {
        if !(1..=22).contains(&l) {
            anyhow::bail!("--zstd {l}: the level must be 1–22");
        }
    }
    let o = ImportOptions {
        levels,
        levels_text,
        max_instances: a.max_instances,
        max_tlas_scratch_bytes: a.max_tlas_scratch,
        max_blas_triangles: a.max_blas_triangles,
        lod_levels: a.lod,
        lod_min_triangles: a.lod_min_triangles,
        zstd_level: a.zstd,
        allow_missing: a.allow_missing,
        pbrt_version: a.pbrt_version,
        subset: a.subset.clone(),
        chunk_bytes: a.chunk_size,
        parallel: a.threads != Some(1),
        curve_ribbons: a.curves == crate::cli::CurvesArg::Ribbons,
        texture_max: a.texture_max,
        ptex_max: a.ptex_max,
        proxy_boxes: !a.no_proxy_boxes,
        proxy_clusters: !a.no_proxy_clusters,
        stream_split_instances: a.stream_split_instances,
        progress: crate::progress::import_bar(),
        // A/B switch for measurements (issue 48): the compile-time cut of the same package.
        cut_while_parsing: std::env::var_os("MOTU_IMPORT_CUT_AT_COMPILE").is_none(),
        // A/B switch (issue 48): cut each mesh before the parser goes on (no overlap).
        cut_queue_bytes: if std::env::var_os("MOTU_IMPORT_CUT_SEQUENTIAL").is_some() {
            0
        } else {
            motu_import::DEFAULT_CUT_QUEUE_BYTES
        },
        // A/B knob (issue 48): chunk bytes the proxy boxes read back at once (main's batch
        // was one 64 MiB chunk per thread, up to 16: 1073741824 at 16 threads).
        proxy_readback_bytes: match std::env::var("MOTU_IMPORT_PROXY_READBACK_BYTES") {
            Ok(v) => v.trim().parse().map_err(|e| {
                anyhow::anyhow!("MOTU_IMPORT_PROXY_READBACK_BYTES={v}: not a byte count ({e})")
            })?,
            Err(_) => motu_import::DEFAULT_PROXY_READBACK_BYTES,
        },
    };
    let s = pipeline::import(&a.scene, &a.output, &o)?;
    if s.meshes == 0 {
        // Not an error (a camera-only scene is valid pbrt), but never silent: it renders empty.
        eprintln!(
            "warning: {} holds no geometry: the package renders as an empty image",
            a.scene.display()
        );
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&s)?);
    } else {
        println!(
            "wrote {} ({}, {} chunks): {} meshes, {} instances ({} flattened), {} TLAS / {} BLAS; parse {:.0} ms, compile {:.0} ms, pack {:.0} ms{}",
            s.package,
            format_size(s.file_bytes),
            s.chunks,
            s.meshes,
            s.instances,
            s.flattened_instances,
            s.tlas_count,
            s.blas_count,
            s.parse_ms,
            s.compile_ms,
            s.pack_ms,
            if s.warnings > 0 { format!("; {} warnings (see `motu info`)", s.warnings) } else { String::new() }
        );
        if s.curve_ribbons > 0 {
            println!(
                "{} curve shapes tessellated as ribbons ({} triangles)",
                s.curve_ribbons, s.curve_ribbon_triangles
            );
        }
        if s.curves_not_converted > 0 {
            println!(
                "note: {} curve shapes were counted but not converted to triangles (--curves ribbons tessellates them)",
                s.curves_not_converted
            );
        }
    }
    Ok(())
}

/// More worker threads than a few per core only add memory and contention: `--threads` above
/// that is capped, with a message. 0 is refused.
pub fn cap_threads(option: &str, requested: usize) -> anyhow::Result<usize> {
    if requested == 0 {
        anyhow::bail!("{option} 0: give at least 1 (or leave it out to use every core)");
    }
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let cap = (4 * cores).max(4);
    if requested > cap {
        eprintln!(
            "warning: {option} {requested} capped at {cap} (4× the {cores} cores of this machine)"
        );
        return Ok(cap);
    }
    Ok(requested)
}
