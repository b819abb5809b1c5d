//! `motu info` and `motu verify`.

use crate::cli::{InfoArgs, VerifyArgs};
use crate::pipeline;
use crate::size::format_size;
use anyhow::Context;

pub fn run(a: InfoArgs) -> anyhow::Result<()> {
    let pkg = pipeline::open(&a.package)?;
    let meta = pkg.meta();
    let view = pkg.view()?;
    let c = &meta.compile;
    let num = |k: &str| c.get(k).and_then(|v| v.as_u64()).unwrap_or(0);
    let p = pkg.package();
    let v = p.format_version();
    if a.elements {
        if a.json {
            println!(
                "{}",
                serde_json::to_string_pretty(&serde_json::json!({ "elements": meta.elements }))?
            );
        } else {
            println!(
                "{:<24} {:>14} {:>16} {:>16} {:>18} {:>12}",
                "element", "instances", "flattened", "unique tris", "instanced tris", "mesh bytes"
            );
            for e in &meta.elements {
                println!(
                    "{:<24} {:>14} {:>16} {:>16} {:>18} {:>12}",
                    e.name,
                    e.instances,
                    e.flattened_instances,
                    e.unique_triangles,
                    e.instanced_triangles,
                    format_size(e.mesh_bytes)
                );
            }
        }
        return Ok(());
    }
    // Ptex textures read with at least one face (a file that could not be read has none).
    let ptex = view
        .textures
        .iter()
        .filter(|t| motu_abi::ptex::is_ptex(t) && t.height > 0);
    let out = serde_json::json!({
        "format_version": format!("{}.{}", v.major, v.minor),
        "schema": meta.schema,
        "source": meta.source,
        "levels": num("tlas_levels"),
        "levels_setting": meta.levels,
        "instances": meta.scene.instances,
        "flattened_instances": meta.scene.flattened_instances,
        "unique_triangles": meta.scene.unique_triangles,
        "instanced_triangles": meta.scene.instanced_triangles,
        "meshes": meta.scene.meshes,
        "compiled_meshes": view.meshes.len(),
        "prototypes": meta.scene.prototypes,
        "nodes": view.tlases.len() + view.blases.len(),
        "tlas_count": view.tlases.len(),
        "blas_count": view.blases.len(),
        "tlas_instances": view.instances.len(),
        "programmable_instances": view.pis.len(),
        "lod_selectors": view.lod_selectors.len(),
        "max_instances_per_tlas": view.tlases.iter().map(|t| t.instance_count).max().unwrap_or(0),
        "max_instances_cap": meta.max_instances_per_tlas,
        "split_tlases": num("split_tlases"),
        "max_blas_triangles": num("max_blas_triangles"),
        "max_triangles_per_blas": view
            .blases
            .iter()
            .filter(|b| b.kind == motu_abi::BLAS_TRIANGLES)
            .map(|b| b.primitive_count)
            .max()
            .unwrap_or(0),
        "partitioned_meshes": num("partitioned_meshes"),
        "partition_clusters": num("partition_clusters"),
        "baked_prototypes": num("baked_prototypes"),
        "inlined_prototypes": num("inlined_prototypes"),
        "chunks": p.chunks().len(),
        "chunk_raw_bytes": p.chunks().iter().map(|c| c.raw_len).sum::<u64>(),
        "chunk_stored_bytes": p.chunks().iter().map(|c| c.stored_len).sum::<u64>(),
        "file_bytes": p.file_bytes(),
        "cameras": meta.cameras.iter().map(|c| c.name.clone()).collect::<Vec<_>>(),
        "elements": meta.elements.iter().map(|e| e.name.clone()).collect::<Vec<_>>(),
        "lights": meta.lights.len(),
        "materials": meta.material_names.len(),
        "warnings": meta.warnings.len(),
        "curves": meta.curves.curves,
        "curve_ribbons": meta.curves.ribbons,
        "curve_ribbon_triangles": meta.curves.ribbon_triangles,
        "ptex_materials": meta.material_ptex.iter().filter(|p| p.is_some()).count(),
    });
    let mut out = out;
    out["ptex_textures"] = ptex.clone().count().into();
    out["ptex_faces"] = ptex
        .clone()
        .map(|t| u64::from(t.height))
        .sum::<u64>()
        .into();
    out["ptex_bytes"] = ptex.map(|t| t.texel_count() * 4).sum::<u64>().into();
    if a.json {
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    let obj = out.as_object().context("info is an object")?;
    for (k, v) in obj {
        let shown = match (k.as_str(), v.as_u64()) {
            ("file_bytes" | "chunk_raw_bytes" | "chunk_stored_bytes" | "ptex_bytes", Some(b)) => {
                format!("{} ({b})", format_size(b))
            }
            _ => match v {
                serde_json::Value::String(s) => s.clone(),
                other => other.to_string(),
            },
        };
        println!("{k:<24} {shown}");
    }
    for w in meta.warnings.iter().take(20) {
        println!("warning: {}", crate::terminal_safe(w));
    }
    Ok(())
}

pub fn verify(a: VerifyArgs) -> anyhow::Result<()> {
    let pkg = motu_package::Package::open(&a.package).with_context(|| {
        format!(
            "opening {} (header, manifest and trailer are checked on open)",
            a.package.display()
        )
    })?;
    let r = pkg
        .verify()
        .with_context(|| format!("verifying {}", a.package.display()))?;
    // The schema layer: meta parses and every cross-table reference and mesh blob is in range.
    pipeline::open(&a.package)?;
    println!(
        "ok: {} ({}): {} chunks, {} sections, {} checksummed, {} padding bytes all zero",
        a.package.display(),
        format_size(r.file_bytes),
        r.chunks,
        r.sections,
        format_size(r.checksummed_bytes),
        r.padding_bytes
    );
    Ok(())
}
