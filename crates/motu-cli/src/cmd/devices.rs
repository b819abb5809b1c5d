//! `motu devices`: every Vulkan device with its ray-tracing support, limits and heap budgets.

use crate::cli::DevicesArgs;
use anyhow::Context;

pub fn run(args: DevicesArgs) -> anyhow::Result<()> {
    let devices = motu_gpu::list_devices().context("listing Vulkan devices")?;
    if args.json {
        // One object on stdout (the contract), the device list under `devices`.
        let out = motu_render::stats::DeviceList::new(&devices);
        println!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        for d in &devices {
            print!("{}", d.to_table_string());
        }
    }
    Ok(())
}
