//! `motu import`: pbrt/OBJ → compiled, chunked scene package.

use crate::cli::{ImportArgs, LevelsArg};
use crate::pipeline::{self, ImportOptions};
use crate::size::format_size;
use motu_compile::Levels;

pub fn run(a: ImportArgs) -> anyhow::Result<()> {
    if let Some(t) = a.threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(t.max(1))
            .build_global()
            .ok();
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
    };
    let s = pipeline::import(&a.scene, &a.output, &o)?;
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
        if s.curves_not_converted > 0 {
            println!(
                "note: {} curve shapes were counted but not converted to triangles (--curves ribbons tessellates them)",
                s.curves_not_converted
            );
        }
    }
    Ok(())
}
