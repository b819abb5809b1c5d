//! The `--html` page: one self-contained file (inline CSS, inline SVG charts, a few lines of
//! inline script for highlighting; no network assets), readable without script too.

use std::fmt::Write;

use crate::cost::Cost;
use crate::human::{human_bytes, human_count};
use crate::report::Report;

/// The stacked segments of every bar: (CSS class, label, bytes of a cost).
type Segment = (&'static str, &'static str, fn(&Cost) -> u64);
const SEGMENTS: [Segment; 6] = [
    ("seg-geometry", "geometry", |c| c.geometry_bytes),
    ("seg-blas", "BLAS (compacted)", |c| c.blas_compacted_bytes),
    ("seg-tlas", "TLAS + instances", |c| c.tlas_total_bytes()),
    ("seg-tables", "record tables", |c| c.table_bytes),
    ("seg-textures", "textures", |c| c.texture_bytes),
    ("seg-transient", "build transient", |c| {
        c.build_transient_peak_bytes
    }),
];

fn esc(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for ch in s.chars() {
        match ch {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&#39;"),
            c => o.push(c),
        }
    }
    o
}

/// A horizontal stacked bar chart: one row per (label, cost), resident segments then the build
/// transient, so a bar's length is its peak; scaled to the largest peak (or the budget line).
fn stacked_chart(id: &str, title: &str, rows: &[(String, Cost)], budget: Option<u64>) -> String {
    let label_w = 170.0;
    let chart_w = 760.0;
    let row_h = 26.0;
    let top = 8.0;
    let max_total = rows
        .iter()
        .map(|(_, c)| c.peak_bytes)
        .chain(budget)
        .max()
        .unwrap_or(1)
        .max(1) as f64;
    let h = top + row_h * rows.len() as f64 + 24.0;
    let mut s = String::new();
    let _ = write!(
        s,
        r#"<figure><figcaption>{}</figcaption><svg id="{id}" class="chart" role="img" aria-label="{}" viewBox="0 0 {} {h}" width="100%">"#,
        esc(title),
        esc(title),
        label_w + chart_w + 90.0
    );
    for (i, (label, c)) in rows.iter().enumerate() {
        let y = top + row_h * i as f64;
        let _ = write!(
            s,
            r#"<text class="label" x="{}" y="{}" text-anchor="end">{}</text>"#,
            label_w - 8.0,
            y + row_h * 0.62,
            esc(label)
        );
        let mut x = label_w;
        for (class, seg_name, f) in SEGMENTS {
            let w = f(c) as f64 / max_total * chart_w;
            if f(c) == 0 {
                continue;
            }
            let _ = write!(
                s,
                r#"<rect class="bar {class}" data-segment="{class}" x="{x:.2}" y="{y:.2}" width="{:.2}" height="{:.2}"><title>{}: {} {}</title></rect>"#,
                w.max(0.5),
                row_h - 6.0,
                esc(label),
                seg_name,
                human_bytes(f(c))
            );
            x += w;
        }
        let _ = write!(
            s,
            r#"<text class="value" x="{:.2}" y="{}">{}</text>"#,
            x + 6.0,
            y + row_h * 0.62,
            human_bytes(c.peak_bytes)
        );
    }
    if let Some(b) = budget {
        let x = label_w + b as f64 / max_total * chart_w;
        let _ = write!(
            s,
            r#"<line class="budget" x1="{x:.2}" x2="{x:.2}" y1="2" y2="{}"/><text class="budget-label" x="{x:.2}" y="{}" text-anchor="middle">budget {}</text>"#,
            h - 18.0,
            h - 4.0,
            human_bytes(b)
        );
    }
    s.push_str("</svg></figure>");
    s
}

fn legend() -> String {
    let mut s = String::from(r#"<div class="legend">"#);
    for (class, name, _) in SEGMENTS {
        let _ = write!(
            s,
            r#"<span class="key" data-segment="{class}"><svg width="14" height="14"><rect class="{class}" width="14" height="14"/></svg> {name}</span>"#
        );
    }
    s.push_str("</div>");
    s
}

fn cost_table(head: &str, rows: &[(String, Vec<String>, Cost)], extra: &[&str]) -> String {
    let mut s = String::from(r#"<div class="scroll"><table><thead><tr>"#);
    let _ = write!(s, "<th>{}</th>", esc(head));
    for h in extra {
        let _ = write!(s, "<th>{}</th>", esc(h));
    }
    for h in [
        "geometry",
        "BLAS",
        "BLAS compacted",
        "TLAS + inst",
        "tables",
        "textures",
        "scratch peak",
        "resident",
        "peak",
    ] {
        let _ = write!(s, "<th>{h}</th>");
    }
    s.push_str("</tr></thead><tbody>");
    for (name, cells, c) in rows {
        let _ = write!(s, "<tr><td>{}</td>", esc(name));
        for cell in cells {
            let _ = write!(s, "<td>{}</td>", esc(cell));
        }
        for v in [
            c.geometry_bytes,
            c.blas_bytes,
            c.blas_compacted_bytes,
            c.tlas_total_bytes(),
            c.table_bytes,
            c.texture_bytes,
            c.build_scratch_peak_bytes,
            c.resident_bytes,
            c.peak_bytes,
        ] {
            let _ = write!(s, r#"<td title="{v} bytes">{}</td>"#, human_bytes(v));
        }
        s.push_str("</tr>");
    }
    s.push_str("</tbody></table></div>");
    s
}

const CSS: &str = "
body{font:14px/1.4 system-ui,-apple-system,'Segoe UI',sans-serif;margin:24px;color:#1d2330;background:#fafbfc}
h1{font-size:22px;margin:0 0 4px}h2{font-size:17px;margin:28px 0 8px}
.meta{color:#555}.note{color:#7a5b00}.warn{color:#a01010;font-weight:600}
figure{margin:8px 0;background:#fff;border:1px solid #dde1e6;border-radius:6px;padding:8px}
figcaption{font-weight:600;margin-bottom:4px}
.chart text{font-size:12px;fill:#1d2330}.chart .value{fill:#555}
.seg-geometry{fill:#4c78a8}.seg-blas{fill:#f58518}.seg-tlas{fill:#54a24b}.seg-tables{fill:#b279a2}.seg-textures{fill:#e45756}.seg-transient{fill:#c7c7c7}
.bar{stroke:#fff;stroke-width:.5}.bar.dim{opacity:.25}
.budget{stroke:#d62728;stroke-width:2;stroke-dasharray:5 3}.budget-label{fill:#d62728!important;font-weight:600}
.legend{margin:6px 0}.key{margin-right:16px;cursor:pointer;user-select:none}.key svg{vertical-align:-2px}
.scroll{overflow-x:auto}table{border-collapse:collapse;background:#fff;margin:6px 0}
th,td{border:1px solid #dde1e6;padding:3px 8px;text-align:right;white-space:nowrap}
th:first-child,td:first-child{text-align:left}th{background:#eef1f5}
code{background:#eef1f5;padding:2px 5px;border-radius:3px}
.fits{color:#1a7f37;font-weight:600}.nofit{color:#a01010;font-weight:600}
";

// Hovering a legend key highlights that segment in every chart; `data-ready` tells tests the
// script ran to its end.
const SCRIPT: &str = "
(function(){
  var keys=document.querySelectorAll('.key');
  keys.forEach(function(k){
    var seg=k.getAttribute('data-segment');
    k.addEventListener('mouseenter',function(){
      document.querySelectorAll('.bar').forEach(function(b){
        if(b.getAttribute('data-segment')!==seg){b.classList.add('dim');}
      });
    });
    k.addEventListener('mouseleave',function(){
      document.querySelectorAll('.bar.dim').forEach(function(b){b.classList.remove('dim');});
    });
  });
  document.getElementById('bar-count').textContent=String(document.querySelectorAll('svg.chart rect.bar').length);
  document.body.setAttribute('data-ready','1');
})();
";

/// The report as one self-contained HTML page.
pub fn render_html(r: &Report) -> String {
    let mut s = String::new();
    let _ = write!(
        s,
        r#"<!DOCTYPE html><html lang="en"><head><meta charset="utf-8"><meta name="viewport" content="width=device-width,initial-scale=1"><title>motu VRAM report: {}</title><style>{CSS}</style></head><body>"#,
        esc(&r.package)
    );
    let _ = write!(s, "<h1>VRAM report: {}</h1>", esc(&r.package));
    let _ = write!(
        s,
        r#"<p class="meta">compiled with <code>--levels {}</code> · sizes: {} ({}) · maxInstanceCount {} · {} unique / {} instanced triangles · {} flattened instances</p>"#,
        esc(&r.levels),
        esc(&r.sizes.kind),
        esc(&r.sizes.device),
        r.max_instance_count,
        human_count(r.unique_triangles),
        human_count(r.instanced_triangles),
        human_count(r.flattened_instances)
    );
    for n in &r.sizes.notes {
        let _ = write!(s, r#"<p class="note">{}</p>"#, esc(n));
    }
    for w in &r.warnings {
        let _ = write!(s, r#"<p class="warn">{}</p>"#, esc(w));
    }
    let budget = r.budget.as_ref().map(|b| b.budget_bytes);

    s.push_str("<h2>Per element (as compiled)</h2>");
    s.push_str(&legend());
    let rows: Vec<(String, Cost)> = r.elements.iter().map(|e| (e.name.clone(), e.ml)).collect();
    s.push_str(&stacked_chart(
        "chart-elements",
        "Bytes per element (resident + build transient = peak)",
        &rows,
        None,
    ));
    let trows: Vec<(String, Vec<String>, Cost)> = r
        .elements
        .iter()
        .map(|e| {
            (
                e.name.clone(),
                vec![
                    human_count(e.root_instances),
                    human_count(e.flattened_instances),
                    human_count(e.instanced_triangles),
                    e.alone.map_or("-".into(), |a| human_bytes(a.peak_bytes)),
                ],
                e.ml,
            )
        })
        .collect();
    s.push_str(&cost_table(
        "element",
        &trows,
        &["root inst", "flat inst", "inst tris", "alone peak"],
    ));

    s.push_str("<h2>Single-level vs multi-level</h2>");
    let rows: Vec<(String, Cost)> = r
        .variants
        .iter()
        .map(|v| (format!("{} ({})", v.name, v.levels), v.cost))
        .collect();
    s.push_str(&stacked_chart(
        "chart-variants",
        "Whole scene: as compiled vs --levels 2 vs sl",
        &rows,
        budget,
    ));
    let trows: Vec<(String, Vec<String>, Cost)> = r
        .variants
        .iter()
        .map(|v| {
            (
                v.name.clone(),
                vec![
                    v.levels.clone(),
                    human_count(v.top_instances),
                    v.top_tlas_pieces.to_string(),
                    if v.exceeds_max_instance_count {
                        "yes".into()
                    } else {
                        "no".into()
                    },
                ],
                v.cost,
            )
        })
        .collect();
    s.push_str(&cost_table(
        "variant",
        &trows,
        &[
            "levels",
            "top instances",
            "top TLASes",
            "over maxInstanceCount",
        ],
    ));

    if let Some(b) = &r.budget {
        let _ = write!(s, "<h2>Budget {}</h2>", human_bytes(b.budget_bytes));
        let rows: Vec<(String, Cost)> = r
            .elements
            .iter()
            .filter_map(|e| e.alone.map(|a| (e.name.clone(), a)))
            .collect();
        s.push_str(&stacked_chart(
            "chart-budget",
            "Each element alone (peak) against the budget",
            &rows,
            Some(b.budget_bytes),
        ));
        match &b.suggestion {
            Some(sg) => {
                let _ = write!(
                    s,
                    r#"<p>Suggested subset ({}): <code id="subset-arg">{}</code> — peak {}, {} instanced triangles ({:.1}%).</p>"#,
                    esc(&sg.method),
                    esc(&sg.subset_arg),
                    human_bytes(sg.cost.peak_bytes),
                    human_count(sg.instanced_triangles),
                    sg.triangle_fraction * 100.0
                );
            }
            None => s.push_str(r#"<p class="nofit">No element fits alone.</p>"#),
        }
        s.push_str("<ul>");
        for v in &b.variants {
            let _ = write!(
                s,
                r#"<li>{}: peak {} — <span class="{}">{}</span></li>"#,
                esc(&v.name),
                human_bytes(v.peak_bytes),
                if v.fits { "fits" } else { "nofit" },
                if v.fits { "fits" } else { "does not fit" }
            );
        }
        let _ = write!(
            s,
            r#"<li>streaming floor {}: <span class="{}">{}</span></li></ul>"#,
            human_bytes(r.streaming.min_resident_bytes),
            if b.streaming_fits { "fits" } else { "nofit" },
            if b.streaming_fits {
                "fits"
            } else {
                "does not fit"
            }
        );
        for n in &b.notes {
            let _ = write!(s, r#"<p class="note">{}</p>"#, esc(n));
        }
    }
    let st = &r.streaming;
    let _ = write!(
        s,
        "<h2>Streaming</h2><p>Always resident {} (record tables + root TLAS); the largest BLAS build needs {} ({}); floor {}. Largest element alone: {} ({}).</p>",
        human_bytes(st.always_resident_bytes),
        human_bytes(st.largest_blas_build_bytes),
        esc(&st.largest_blas_owner),
        human_bytes(st.min_resident_bytes),
        esc(st.largest_element.as_deref().unwrap_or("-")),
        human_bytes(st.largest_element_peak_bytes)
    );
    let _ = write!(
        s,
        r#"<p class="meta">chart bars: <span id="bar-count">(script did not run)</span></p><script>{SCRIPT}</script></body></html>"#
    );
    s
}
