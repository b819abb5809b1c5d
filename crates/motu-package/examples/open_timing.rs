//! Times one `Package::open` (and optionally `verify`) of a package, for cold-cache
//! measurements the criterion bench cannot make: `cargo run --release -p motu-package
//! --example open_timing -- PKG [--verify]`.

use std::time::Instant;

fn main() -> Result<(), motu_package::PackageError> {
    let mut args = std::env::args().skip(1);
    let Some(path) = args.next() else {
        eprintln!("usage: open_timing PKG [--verify]");
        std::process::exit(2);
    };
    let start = Instant::now();
    let package = motu_package::Package::open(&path)?;
    let open_ms = start.elapsed().as_secs_f64() * 1e3;
    println!(
        "open: {open_ms:.3} ms ({} bytes, {} chunks, {} sections)",
        package.file_bytes(),
        package.chunk_count(),
        package.sections().len()
    );
    if args.next().as_deref() == Some("--verify") {
        let start = Instant::now();
        let report = package.verify()?;
        let seconds = start.elapsed().as_secs_f64();
        println!(
            "verify: {:.3} s, {:.2} GiB/s",
            seconds,
            report.file_bytes as f64 / seconds / (1u64 << 30) as f64
        );
    }
    Ok(())
}
