//! `motu info` and `motu verify`.

use crate::cli::{InfoArgs, VerifyArgs};
use crate::pipeline;
use crate::size::format_size;
use anyhow::Context;

pub fn run(a: InfoArgs) -> anyhow::Result<()> {
    let pkg = pipeline::open(&a.package)?;
    let meta = pkg.meta();
    let view = pkg.view()?;
    if a.elements {
        if a.json {
            let out = motu_pack::ElementsInfo {
                elements: &meta.elements,
            };
            println!("{}", serde_json::to_string_pretty(&out)?);
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
    let info = motu_pack::PackageInfo::new(&pkg, &view);
    if a.json {
        println!("{}", serde_json::to_string_pretty(&info)?);
        return Ok(());
    }
    // The text form: one line a key, in key order.
    let out = serde_json::to_value(&info)?;
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
