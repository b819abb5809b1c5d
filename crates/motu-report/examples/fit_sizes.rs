//! Fits the size model on the default ray-tracing device (`MOTU_DEVICE` picks another):
//! `cargo run -p motu-report --example fit_sizes` prints the fit as JSON;
//! `... -- --preset NAME` prints it as a preset data file for `presets/NAME.json`.
fn main() -> Result<(), Box<dyn std::error::Error>> {
    let ctx = motu_gpu::Context::new(&motu_gpu::ContextOptions {
        require: motu_gpu::Requirement::RayTracing,
        ..Default::default()
    })?;
    let fit = motu_report::fit_device(&ctx)?;
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.as_slice() {
        [flag, name] if flag == "--preset" => {
            let ratio = motu_report::nearest_preset(ctx.device_name()).compaction_ratio;
            print!("{}", fit.to_preset(name, ratio)?.to_json());
        }
        [] => println!("{}", serde_json::to_string_pretty(&fit)?),
        _ => return Err("usage: fit_sizes [--preset NAME]".into()),
    }
    Ok(())
}
