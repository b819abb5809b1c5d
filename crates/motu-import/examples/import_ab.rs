//! `motu import SCENE -o OUT --json` without the CLI (a release build of only the import's
//! crates, for A/B measurements on busy machines), with the CLI's A/B switches
//! (`MOTU_IMPORT_CUT_AT_COMPILE`, `MOTU_IMPORT_CUT_SEQUENTIAL`; `MOTU_IMPORT_CUT_QUEUE_MIB` sets
//! the cutting queue's bound) and a resident-memory trace:
//! every 100 ms the process's `VmRSS`, printed after the summary as `rss_trace_mib`.
//!
//! `cargo run --release -p motu-import --example import_ab -- SCENE OUT`

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

fn rss_mib() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find(|l| l.starts_with("VmRSS:"))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|k| k.parse::<u64>().ok())
        .map_or(0, |kib| kib / 1024)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let [_, scene, out] = args.as_slice() else {
        return Err("usage: import_ab SCENE OUT".into());
    };
    let o = motu_import::ImportOptions {
        cut_while_parsing: std::env::var_os("MOTU_IMPORT_CUT_AT_COMPILE").is_none(),
        cut_queue_bytes: match std::env::var("MOTU_IMPORT_CUT_QUEUE_MIB") {
            _ if std::env::var_os("MOTU_IMPORT_CUT_SEQUENTIAL").is_some() => 0,
            Ok(mib) => mib.parse::<u64>()? << 20,
            Err(_) => motu_import::DEFAULT_CUT_QUEUE_BYTES,
        },
        ..Default::default()
    };
    let stop = Arc::new(AtomicBool::new(false));
    let t0 = Instant::now();
    let sampler = {
        let stop = stop.clone();
        std::thread::spawn(move || {
            let mut trace = Vec::new();
            while !stop.load(Ordering::Relaxed) {
                trace.push((t0.elapsed().as_millis() as u64, rss_mib()));
                std::thread::sleep(Duration::from_millis(100));
            }
            trace
        })
    };
    let s = motu_import::import(scene.as_ref(), out.as_ref(), &o)?;
    stop.store(true, Ordering::Relaxed);
    let trace = sampler.join().map_err(|_| "sampler panicked")?;
    let mut v = serde_json::to_value(&s)?;
    v["rss_trace_mib"] = serde_json::to_value(trace)?;
    println!("{}", serde_json::to_string(&v)?);
    Ok(())
}
