//! Prints what `motu devices` shows: `cargo run -p motu-gpu --example devices [-- --json]`.

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let json = std::env::args().any(|a| a == "--json");
    let devices = motu_gpu::list_devices()?;
    if json {
        println!("{}", serde_json::to_string_pretty(&devices)?);
    } else {
        for d in &devices {
            print!("{}", d.to_table_string());
        }
    }
    Ok(())
}
