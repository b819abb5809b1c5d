//! `motu gen`: procedural pbrt scenes.

use crate::cli::{GenArgs, GenKindArg};
use crate::progress::Progress;
use anyhow::{bail, Context};
use motu_gen::{
    CourtyardOptions, ForestOptions, GenKind, GridSize, IslandOptions, LodGridOptions,
    SphereflakeOptions,
};

fn reject(flag: &str, given: bool, kind: &str) -> anyhow::Result<()> {
    if given {
        bail!("{flag} does not apply to `motu gen {kind}` (see `motu gen --help`)");
    }
    Ok(())
}

pub fn options(a: &GenArgs) -> anyhow::Result<GenKind> {
    if a.threads == Some(0) {
        // As `motu import` refuses it, for every kind.
        super::import::cap_threads("--threads", 0)?;
    }
    let grid = a
        .grid
        .as_deref()
        .map(|g| {
            g.parse::<GridSize>()
                .map_err(|e| anyhow::anyhow!("--grid {g}: {e}"))
        })
        .transpose()?;
    if !matches!(a.kind, GenKindArg::Island) {
        let kind = clap::ValueEnum::to_possible_value(&a.kind)
            .map_or_else(String::new, |v| v.get_name().to_string());
        reject(
            "--max-mesh-triangles",
            a.max_mesh_triangles.is_some(),
            &kind,
        )?;
        reject("--terrain-objects", a.terrain_objects, &kind)?;
        reject(
            "--format json",
            a.format == crate::cli::GenFormatArg::Json,
            &kind,
        )?;
    }
    let kind = match a.kind {
        GenKindArg::Forest => {
            let mut o = ForestOptions::default();
            o.levels = a.levels.unwrap_or(o.levels);
            o.grid = grid.unwrap_or(o.grid);
            o.leaves = a.leaves.unwrap_or(o.leaves);
            o.trunk_segments = a.trunk_segments.unwrap_or(o.trunk_segments);
            o.seed = a.seed.unwrap_or(o.seed);
            o.flat = a.flat;
            o.width = a.width.unwrap_or(o.width);
            o.height = a.height.unwrap_or(o.height);
            for (f, g) in [
                ("--depth", a.depth.is_some()),
                ("--scale", a.scale.is_some()),
                ("--triangles", a.triangles.is_some()),
            ] {
                reject(f, g, "forest")?;
            }
            GenKind::Forest(o)
        }
        GenKindArg::Sphereflake => {
            let mut o = SphereflakeOptions::default();
            o.depth = a.depth.unwrap_or(o.depth);
            o.sphere_segments = a.sphere_segments.unwrap_or(o.sphere_segments);
            o.seed = a.seed.unwrap_or(o.seed);
            o.flat = a.flat;
            o.width = a.width.unwrap_or(o.width);
            o.height = a.height.unwrap_or(o.height);
            for (f, g) in [
                ("--levels", a.levels.is_some()),
                ("--scale", a.scale.is_some()),
                ("--grid", a.grid.is_some()),
            ] {
                reject(f, g, "sphereflake")?;
            }
            GenKind::Sphereflake(o)
        }
        GenKindArg::LodGrid => {
            let mut o = LodGridOptions::default();
            o.grid = grid.unwrap_or(o.grid);
            o.triangles = a.triangles.unwrap_or(o.triangles);
            o.spacing = a.spacing.unwrap_or(o.spacing);
            o.seed = a.seed.unwrap_or(o.seed);
            o.width = a.width.unwrap_or(o.width);
            o.height = a.height.unwrap_or(o.height);
            reject("--flat", a.flat, "lod-grid")?;
            GenKind::LodGrid(o)
        }
        GenKindArg::Island => {
            let mut o = IslandOptions::default();
            o.scale = a.scale.unwrap_or(o.scale);
            o.elements = a.elements.or(o.elements);
            o.threads = a
                .threads
                .map(|t| super::import::cap_threads("--threads", t))
                .transpose()?
                .or(o.threads);
            o.max_mesh_triangles = a.max_mesh_triangles.unwrap_or(o.max_mesh_triangles);
            o.terrain_objects = a.terrain_objects;
            if a.format == crate::cli::GenFormatArg::Json {
                o.format = motu_gen::IslandFormat::MoanaJson;
            }
            o.seed = a.seed.unwrap_or(o.seed);
            o.width = a.width.unwrap_or(o.width);
            o.height = a.height.unwrap_or(o.height);
            reject(
                "--flat (island is always standard single-level pbrt-v3)",
                a.flat,
                "island",
            )?;
            GenKind::Island(o)
        }
        GenKindArg::Courtyard => {
            let mut o = CourtyardOptions::default();
            o.width = a.width.unwrap_or(o.width);
            o.height = a.height.unwrap_or(o.height);
            for (f, g) in [
                ("--levels", a.levels.is_some()),
                ("--grid", a.grid.is_some()),
                ("--depth", a.depth.is_some()),
                ("--scale", a.scale.is_some()),
                ("--triangles", a.triangles.is_some()),
                ("--seed", a.seed.is_some()),
                ("--flat", a.flat),
            ] {
                reject(f, g, "courtyard")?;
            }
            GenKind::Courtyard(o)
        }
    };
    Ok(kind)
}

pub fn run(a: GenArgs) -> anyhow::Result<()> {
    let kind = options(&a)?;
    // Written whole into a temp directory beside the target and renamed into place: a failure
    // (full disk, a bad option found while writing) leaves nothing, never a cut scene.
    let out = crate::output::OutputDir::begin("-o", &a.output, a.force)?;
    let progress = Progress::bytes("writing pbrt");
    let mut summary = motu_gen::generate(&kind, out.path(), &mut |p| {
        progress.set(p.bytes_written, None);
    })
    .with_context(|| format!("generating {} into {}", kind.name(), a.output.display()))?;
    if let Ok(rel) = summary.scene_path.strip_prefix(out.path()) {
        summary.scene_path = a.output.join(rel);
    }
    let entry = summary
        .scene_path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    out.commit(&entry)?;
    progress.finish();
    if a.json {
        let out = serde_json::json!({
            "scene": summary.scene_path,
            "files_written": summary.files_written,
            "bytes_written": summary.bytes_written,
            "object_instances": summary.object_instances,
            "flattened_instances": summary.flattened_instances,
            "unique_triangles": summary.unique_triangles,
            "instanced_triangles": summary.instanced_triangles,
            "elements": summary.elements,
            "cameras": summary.cameras,
            "nested_instancing": summary.nested_instancing,
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        println!(
            "wrote {} ({} files, {}): {} ObjectInstance, {} flattened instances, {} unique / {} instanced triangles{}",
            summary.scene_path.display(),
            summary.files_written,
            crate::size::format_size(summary.bytes_written),
            summary.object_instances,
            summary.flattened_instances,
            summary.unique_triangles,
            summary.instanced_triangles,
            if summary.nested_instancing { " (nested instancing: a motu extension)" } else { "" }
        );
    }
    Ok(())
}
