//! The terminal table.

use std::fmt::Write;

use crate::cost::Cost;
use crate::human::{human_bytes, human_count};
use crate::report::Report;

fn row(out: &mut String, cells: &[String], widths: &[usize]) {
    for (i, (c, w)) in cells.iter().zip(widths).enumerate() {
        if i == 0 {
            let _ = write!(out, "{c:<w$}");
        } else {
            let _ = write!(out, "  {c:>w$}");
        }
    }
    out.push('\n');
}

fn table(out: &mut String, header: &[&str], rows: &[Vec<String>]) {
    let mut widths: Vec<usize> = header.iter().map(|h| h.chars().count()).collect();
    for r in rows {
        for (w, c) in widths.iter_mut().zip(r) {
            *w = (*w).max(c.chars().count());
        }
    }
    let head: Vec<String> = header.iter().map(|s| s.to_string()).collect();
    row(out, &head, &widths);
    let total: usize = widths.iter().sum::<usize>() + 2 * (widths.len().saturating_sub(1));
    out.push_str(&"-".repeat(total));
    out.push('\n');
    for r in rows {
        row(out, r, &widths);
    }
}

fn cost_cells(c: &Cost) -> Vec<String> {
    vec![
        human_bytes(c.geometry_bytes),
        human_bytes(c.blas_bytes),
        human_bytes(c.blas_compacted_bytes),
        human_bytes(c.tlas_total_bytes()),
        human_bytes(c.table_bytes),
        human_bytes(c.texture_bytes),
        human_bytes(c.build_scratch_peak_bytes),
        human_bytes(c.resident_bytes),
        human_bytes(c.peak_bytes),
    ]
}

const COST_HEADER: [&str; 9] = [
    "geometry",
    "BLAS",
    "BLAS compact",
    "TLAS+inst",
    "tables",
    "textures",
    "scratch",
    "resident",
    "peak",
];

/// The report as a terminal table (what `motu report` prints without `--json`).
pub fn render_text(r: &Report) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "VRAM report: {} (compiled --levels {})",
        r.package, r.levels
    );
    let _ = writeln!(
        out,
        "sizes: {} — {}; maxInstanceCount {}",
        r.sizes.kind, r.sizes.device, r.max_instance_count
    );
    for n in &r.sizes.notes {
        let _ = writeln!(out, "  note: {n}");
    }
    let _ = writeln!(
        out,
        "scene: {} unique triangles, {} instanced triangles, {} flattened instances\n",
        human_count(r.unique_triangles),
        human_count(r.instanced_triangles),
        human_count(r.flattened_instances)
    );

    let _ = writeln!(
        out,
        "Per element (as compiled; `alone` = rendered with --subset NAME):"
    );
    let mut header = vec!["element", "root inst", "flat inst", "inst tris"];
    header.extend(COST_HEADER);
    header.push("alone peak");
    let rows: Vec<Vec<String>> = r
        .elements
        .iter()
        .map(|e| {
            let mut v = vec![
                e.name.clone(),
                human_count(e.root_instances),
                human_count(e.flattened_instances),
                human_count(e.instanced_triangles),
            ];
            v.extend(cost_cells(&e.ml));
            v.push(e.alone.map_or("-".into(), |a| human_bytes(a.peak_bytes)));
            v
        })
        .collect();
    table(&mut out, &header, &rows);

    let _ = writeln!(out, "\nSingle-level vs multi-level (whole scene):");
    let mut header = vec!["variant", "top inst", "TLASes", "BLASes"];
    header.extend(COST_HEADER);
    let rows: Vec<Vec<String>> = r
        .variants
        .iter()
        .map(|v| {
            let mut name = format!("{} ({})", v.name, v.levels);
            if v.exceeds_max_instance_count {
                name.push_str(&format!(" ! {} TLAS splits", v.top_tlas_pieces));
            }
            let mut cells = vec![
                name,
                human_count(v.top_instances),
                v.cost.tlas_count.to_string(),
                v.cost.blas_count.to_string(),
            ];
            cells.extend(cost_cells(&v.cost));
            cells
        })
        .collect();
    table(&mut out, &header, &rows);
    if let Some(sl) = r.variant("sl") {
        let verdict = if sl.exceeds_max_instance_count {
            format!(
                "exceeds maxInstanceCount {} ({} instances): needs {} TLASes",
                r.max_instance_count, sl.top_instances, sl.top_tlas_pieces
            )
        } else {
            "fits in one TLAS".into()
        };
        let _ = writeln!(out, "sl: {verdict}");
    }

    let o = &r.render_overhead;
    let _ = writeln!(
        out,
        "peak = resident + the largest build's transient + what rendering {}×{} needs besides: {} (frame buffers {}, staging ring {}, allocator slack {}); the least --vram-budget the full build renders under",
        r.image_width,
        r.image_height,
        human_bytes(o.total_bytes),
        human_bytes(o.frame_bytes),
        human_bytes(o.staging_bytes),
        human_bytes(o.allocator_slack_bytes),
    );

    let s = &r.streaming;
    let _ = writeln!(
        out,
        "\nStreaming: always resident {} (tables + root TLAS); largest BLAS build {} ({}); floor {}; largest element alone {} ({})",
        human_bytes(s.always_resident_bytes),
        human_bytes(s.largest_blas_build_bytes),
        s.largest_blas_owner,
        human_bytes(s.min_resident_bytes),
        human_bytes(s.largest_element_peak_bytes),
        s.largest_element.as_deref().unwrap_or("-")
    );
    let _ = writeln!(
        out,
        "  streamed meshes {} (in host memory on a discrete GPU, outside the VRAM budget: --stream-mesh-memory)",
        human_bytes(s.mesh_bytes)
    );
    if let Some(whole) = r.variants.first() {
        if s.min_resident_bytes >= whole.cost.peak_bytes {
            let _ = writeln!(
                out,
                "  the streaming floor is not below the full build's peak {}: render without --stream",
                human_bytes(whole.cost.peak_bytes)
            );
        }
    }

    if let Some(sp) = &s.stream_split {
        let _ = writeln!(
            out,
            "  streaming splits {} {} over {} instances into {} pieces when it loads the package, rebuilt one at a time (--stream-split-instances; the floor above is the split hierarchy's)",
            sp.tlases_split,
            if sp.tlases_split == 1 { "TLAS" } else { "TLASes" },
            sp.cap_instances,
            sp.pieces
        );
    }

    if let Some(p) = s.persistent_tlas.as_ref().filter(|p| p.tlases > 0) {
        let _ = writeln!(
            out,
            "  persistent TLASes (--stream-tlas update): {} {} over {} instances would keep {} resident; {}",
            p.tlases,
            if p.tlases == 1 { "TLAS" } else { "TLASes" },
            p.instances,
            human_bytes(p.bytes),
            match p.auto_min_budget_bytes {
                Some(b) => format!(
                    "auto updates them at budgets from {}, rebuilds below",
                    human_bytes(b)
                ),
                None => "auto rebuilds them (fewer than 2^20 instances: a rebuild is cheap)".into(),
            }
        );
    }

    if let Some(b) = &r.budget {
        let _ = writeln!(out, "\nBudget {}:", human_bytes(b.budget_bytes));
        for v in &b.variants {
            let _ = writeln!(
                out,
                "  {:<12} {:>10}  {}",
                v.name,
                human_bytes(v.peak_bytes),
                if v.fits { "fits" } else { "does not fit" }
            );
        }
        let fit: Vec<&str> = b
            .elements
            .iter()
            .filter(|e| e.fits)
            .map(|e| e.name.as_str())
            .collect();
        let no: Vec<&str> = b
            .elements
            .iter()
            .filter(|e| !e.fits)
            .map(|e| e.name.as_str())
            .collect();
        let _ = writeln!(
            out,
            "  fit alone: {}",
            if fit.is_empty() {
                "none".into()
            } else {
                fit.join(", ")
            }
        );
        if !no.is_empty() {
            let _ = writeln!(out, "  too big alone: {}", no.join(", "));
        }
        match &b.suggestion {
            Some(s) => {
                let _ = writeln!(
                    out,
                    "  suggestion ({}): {}  — peak {}, {} instanced triangles ({:.1}%)",
                    s.method,
                    s.subset_arg,
                    human_bytes(s.cost.peak_bytes),
                    human_count(s.instanced_triangles),
                    s.triangle_fraction * 100.0
                );
            }
            None => {
                let _ = writeln!(out, "  suggestion: none fits");
            }
        }
        let _ = writeln!(
            out,
            "  streaming floor {}: {}",
            human_bytes(r.streaming.min_resident_bytes),
            if b.streaming_fits {
                "fits"
            } else {
                "does not fit"
            }
        );
        for n in &b.notes {
            let _ = writeln!(out, "  note: {n}");
        }
    }
    for w in &r.warnings {
        let _ = writeln!(out, "warning: {w}");
    }
    out
}
