//! The report as text: the terminal table and the Markdown table.

use crate::plan::Source;
use crate::report::BenchReport;
use motu_report::format_size;

const MIB: f64 = 1024.0 * 1024.0;

fn mb(b: u64) -> String {
    format!("{:.1}", b as f64 / MIB)
}

fn opt_ratio(r: Option<f64>) -> String {
    match r {
        Some(v) if v >= 100.0 => format!("{v:.0}×"),
        Some(v) => format!("{v:.2}×"),
        None => "–".into(),
    }
}

const HEADER: [&str; 17] = [
    "scene",
    "config",
    "TLAS/BLAS",
    "import s",
    "import RSS MB",
    "compile ms",
    "AS build ms",
    "BLAS MB built→compacted",
    "AS MB",
    "ms/frame",
    "FPS",
    "Mrays/s",
    "traces/ray",
    "overflows",
    "rays/s vs sl",
    "AS sl/x",
    "status",
];

fn rows(report: &BenchReport) -> Vec<[String; 17]> {
    let mut out = Vec::new();
    for s in &report.scenes {
        for c in &s.configs {
            let i = c.import.as_ref();
            let m = c.render.as_ref();
            let f = |x: Option<String>| x.unwrap_or_else(|| "–".into());
            out.push([
                s.name.to_string(),
                c.label.clone(),
                f(i.map(|i| format!("{}/{}", i.tlas_count, i.blas_count))),
                f(i.map(|i| format!("{:.2}", i.wall_s))),
                f(i.map(|i| mb(i.peak_rss_bytes))),
                f(i.map(|i| format!("{:.0}", i.compile_ms))),
                f(m.map(|m| format!("{:.0}", m.as_build_ms))),
                f(m.map(|m| format!("{}→{}", mb(m.blas_bytes), mb(m.blas_compacted_bytes)))),
                f(m.map(|m| mb(m.as_bytes))),
                f(m.map(|m| format!("{:.2}", m.ms_per_frame))),
                f(m.map(|m| format!("{:.1}", m.fps))),
                f(m.map(|m| format!("{:.1}", m.rays_per_second / 1e6))),
                f(m.map(|m| format!("{:.2}", m.traces_per_ray))),
                f(m.map(|m| m.stack_overflows.to_string())),
                opt_ratio(c.ratios.rays_per_second_vs_sl),
                opt_ratio(c.ratios.as_bytes_sl_over_this),
                match c.status {
                    "ok" => "ok".into(),
                    "skipped" => "skipped".into(),
                    _ => "FAILED".into(),
                },
            ]);
        }
    }
    out
}

pub(crate) fn failures(report: &BenchReport) -> Vec<String> {
    let mut out = Vec::new();
    for s in &report.scenes {
        for w in &s.warnings {
            out.push(format!("{}: warning: {w}", s.name));
        }
        for c in &s.configs {
            if let Some(e) = &c.error {
                out.push(format!("{}/{}: {e}", s.name, c.label));
            }
        }
    }
    out
}

fn header_lines(r: &BenchReport) -> Vec<String> {
    let st = &r.settings;
    let m = &r.machine;
    vec![
        format!(
            "suite {}{}: {}×{}, backend {}, median of {} timed frames after {} warm-up frame(s)",
            st.suite,
            if st.quick && st.suite != "quick" {
                " (quick)"
            } else {
                ""
            },
            st.width,
            st.height,
            st.backend,
            st.frames,
            st.warmup_frames
        ),
        format!(
            "machine: {} — {} ({} cores, {} RAM), {}",
            m.hostname,
            m.cpu,
            m.cpu_cores,
            format_size(m.memory_bytes),
            m.os
        ),
        format!(
            "device: {}{}",
            m.device.as_deref().unwrap_or("none (CPU backend)"),
            m.driver
                .as_deref()
                .map(|d| format!(", driver {d}"))
                .unwrap_or_default()
        ),
        format!("commit {}, motu {}", r.commit, r.motu_version),
        format!("command: {}", r.command),
    ]
}

/// The terminal table `motu bench` prints (header lines, one row per configuration,
/// failures, a summary line), each line ending in a newline.
pub fn text_table(r: &BenchReport) -> String {
    let mut out = String::new();
    let mut println = |l: String| {
        out.push_str(&l);
        out.push('\n');
    };
    for l in header_lines(r) {
        println(l);
    }
    let rows = rows(r);
    let mut widths: Vec<usize> = HEADER.iter().map(|h| h.chars().count()).collect();
    for row in &rows {
        for (w, cell) in widths.iter_mut().zip(row.iter()) {
            *w = (*w).max(cell.chars().count());
        }
    }
    let line = |cells: Vec<&str>| {
        let mut s = String::new();
        for (i, (c, w)) in cells.iter().zip(&widths).enumerate() {
            let pad = w.saturating_sub(c.chars().count());
            if i < 2 {
                s.push_str(c);
                s.push_str(&" ".repeat(pad));
            } else {
                s.push_str(&" ".repeat(pad));
                s.push_str(c);
            }
            s.push_str("  ");
        }
        s.trim_end().to_string()
    };
    println(String::new());
    println(line(HEADER.to_vec()));
    for row in &rows {
        println(line(row.iter().map(String::as_str).collect()));
    }
    let f = failures(r);
    if !f.is_empty() {
        println(String::new());
        for l in f {
            println(l);
        }
    }
    println(format!(
        "\n{} configurations, {} failed, {} skipped, {:.1} s in all; logs and renders in {}",
        r.configurations,
        r.failures,
        r.skipped,
        r.total_s,
        r.work_dir.display()
    ));
    out
}

/// The results as a Markdown table (`--markdown`, for BENCHMARKS.md).
pub fn markdown(r: &BenchReport) -> String {
    let mut s = String::new();
    for l in header_lines(r) {
        s.push_str(&format!("- {l}\n"));
    }
    s.push('\n');
    s.push_str(&format!("| {} |\n", HEADER.join(" | ")));
    s.push_str(&format!(
        "|{}\n",
        HEADER
            .iter()
            .enumerate()
            .map(|(i, _)| if i < 2 { "---|" } else { "---:|" })
            .collect::<String>()
    ));
    for row in rows(r) {
        s.push_str(&format!("| {} |\n", row.join(" | ")));
    }
    let notes: Vec<String> = r
        .scenes
        .iter()
        .filter(|sc| !sc.note.is_empty())
        .map(|sc| {
            let src = match &sc.source {
                Source::Gen { args } => format!("`motu gen {}`", args.join(" ")),
                Source::Shared { path } => format!(
                    "`{}`",
                    path.file_name()
                        .map(|f| f.to_string_lossy().to_string())
                        .unwrap_or_default()
                ),
            };
            let inst = sc
                .gen
                .as_ref()
                .and_then(|g| g["flattened_instances"].as_u64())
                .map(|n| format!(", {n} flattened instances"))
                .unwrap_or_default();
            format!("- {}: {src}{inst}; {}\n", sc.name, sc.note)
        })
        .collect();
    if !notes.is_empty() {
        s.push('\n');
        for n in notes {
            s.push_str(&n);
        }
    }
    let f = failures(r);
    if !f.is_empty() {
        s.push('\n');
        for l in f {
            s.push_str(&format!("- {}\n", l.replace('|', "\\|")));
        }
    }
    s
}
