//! `motu report` before the CLI wires it, plus a model check on real packages:
//! `cargo run -p motu-report --example report_package -- PKG [--budget SIZE] [--json]
//! [--html FILE] [--model PRESET] [--compare]`. `--compare` builds the report from the driver
//! and from the device's preset and prints the largest relative error per variant/element.
use motu_report::*;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let pkg_path = args.first().ok_or("usage: report_package PKG [options]")?;
    let opt = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
            .cloned()
    };
    let flag = |name: &str| args.iter().any(|a| a == name);
    let budget = opt("--budget")
        .map(|s| motu_gpu::parse_size(&s))
        .transpose()?;
    let pkg = motu_pack::ScenePackage::open(std::path::Path::new(pkg_path))?;
    let sizes: Box<dyn SizeSource> = match opt("--model") {
        Some(name) => Box::new(ModelSizes::new(preset(&name).ok_or("unknown preset")?)),
        None => size_source_for_cli(None)?,
    };
    let report = build_report(&pkg, sizes.as_ref(), budget)?;
    if flag("--compare") {
        let gpu = GpuSizes::open(None)?;
        let device = gpu.context().device_name().to_string();
        let p = preset_for_device(&device).ok_or("no preset fitted on this device")?;
        let d = build_report(&pkg, &gpu, budget)?;
        let m = build_report(&pkg, &ModelSizes::new(p), budget)?;
        let mut worst = (0.0f64, String::new());
        let mut rows: Vec<(String, Cost, Cost)> = d
            .variants
            .iter()
            .zip(&m.variants)
            .map(|(a, b)| (a.name.clone(), a.cost, b.cost))
            .collect();
        rows.extend(
            d.elements
                .iter()
                .zip(&m.elements)
                .map(|(a, b)| (a.name.clone(), a.ml, b.ml)),
        );
        for (name, dc, mc) in rows {
            for (what, dv, mv) in [
                ("blas", dc.blas_bytes, mc.blas_bytes),
                ("tlas", dc.tlas_bytes, mc.tlas_bytes),
                (
                    "scratch",
                    dc.build_scratch_peak_bytes,
                    mc.build_scratch_peak_bytes,
                ),
                ("peak", dc.peak_bytes, mc.peak_bytes),
            ] {
                let e = relative_error(mv, dv);
                if e > worst.0 {
                    worst = (e, format!("{name} {what}: model {mv} vs driver {dv}"));
                }
            }
        }
        println!(
            "{pkg_path} on {device}: worst model error {:.2}% ({}); driver peak {} as compiled, {} sl",
            worst.0 * 100.0,
            worst.1,
            human_bytes(d.total().peak_bytes),
            human_bytes(d.variant("sl").map_or(0, |v| v.cost.peak_bytes))
        );
        return Ok(());
    }
    if let Some(path) = opt("--html") {
        std::fs::write(path, render_html(&report))?;
    }
    if flag("--json") {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", render_text(&report));
    }
    Ok(())
}
