//! Prints the table `motu devices` shows: `cargo run -p motu-gpu --example devices` (the JSON
//! form, `motu devices --json`, is `motu_render::stats::DeviceList`).

fn main() -> Result<(), Box<dyn std::error::Error>> {
    for d in &motu_gpu::list_devices()? {
        print!("{}", d.to_table_string());
    }
    Ok(())
}
