//! `motu report`: what a scene costs on a GPU, single- versus multi-level, per element, and
//! which subset fits a budget.

use crate::cli::ReportArgs;
use anyhow::Context;

pub fn run(a: ReportArgs) -> anyhow::Result<()> {
    let outputs: Vec<(&str, &std::path::Path)> = a
        .html
        .as_deref()
        .map(|p| ("--html", p))
        .into_iter()
        .collect();
    let mut outs = crate::output::Outputs::begin(&[("package", &a.package)], &outputs)?;
    let t = std::time::Instant::now();
    let pkg = crate::pipeline::open(&a.package)?;
    let open_ms = t.elapsed().as_secs_f64() * 1e3;
    let t = std::time::Instant::now();
    let sizes: Box<dyn motu_report::SizeSource> = if a.measure {
        // Build and compact everything on the device: compacted sizes are measured, not modelled.
        let mut g = motu_report::GpuSizes::open(a.device)
            .context("--measure needs a ray-tracing device")?;
        let ratio = g
            .measure_compaction(&pkg)
            .context("building the package on the device for --measure")?;
        eprintln!("measured BLAS compaction on this device: {ratio:.3} of the built size");
        Box::new(g)
    } else {
        motu_report::size_source_for_cli(a.device)
            .context("opening the --device for acceleration-structure size queries")?
    };
    let size_source_ms = t.elapsed().as_secs_f64() * 1e3;
    // The floor's image size as `motu render` picks it (camera film, one side scaled).
    let floor_image = if a.width.is_some() || a.height.is_some() {
        let view = pkg.view().context("reading the package's hierarchy")?;
        let (_, w, h) = crate::cmd::render::camera_pose(&pkg, &view, None, a.width, a.height)?;
        Some((w, h))
    } else {
        None
    };
    let t = std::time::Instant::now();
    let mut r = motu_report::build_report_at(&pkg, sizes.as_ref(), a.budget, floor_image)
        .with_context(|| format!("VRAM report of {}", a.package.display()))?;
    // The whole command's phases: opening (checksums, reference checks), the size source (a
    // device), the report itself.
    let timings = &mut r.provenance.timings_ms;
    timings.add("open", open_ms);
    timings.add("size_source", size_source_ms);
    timings.add("report", t.elapsed().as_secs_f64() * 1e3);
    if let Some(p) = &a.html {
        outs.write(p, motu_report::render_html(&r).as_bytes())?;
    }
    outs.commit()?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        print!("{}", motu_report::render_text(&r));
    }
    Ok(())
}
