//! `motu report`: what a scene costs on a GPU, single- versus multi-level, per element, and
//! which subset fits a budget.

use crate::cli::ReportArgs;
use anyhow::Context;

pub fn run(a: ReportArgs) -> anyhow::Result<()> {
    if a.measure {
        eprintln!("note: --measure (built and compacted sizes) is not implemented yet; sizes come from the driver's build-size queries, compaction from the model");
    }
    let pkg = crate::pipeline::open(&a.package)?;
    let sizes = motu_report::size_source_for_cli(a.device)
        .context("opening the --device for acceleration-structure size queries")?;
    let r = motu_report::build_report(&pkg, sizes.as_ref(), a.budget)
        .with_context(|| format!("VRAM report of {}", a.package.display()))?;
    if let Some(p) = &a.html {
        std::fs::write(p, motu_report::render_html(&r))
            .with_context(|| format!("writing {}", p.display()))?;
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        print!("{}", motu_report::render_text(&r));
    }
    Ok(())
}
