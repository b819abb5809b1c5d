//! Byte sizes and counts for people (`1.50 GiB`, `15.3G`), shared by every output format.

use motu_alloc::binary_scale;

/// `1.50 GiB`, `12.0 MiB`, `640 B`.
pub fn human_bytes(bytes: u64) -> String {
    match binary_scale(bytes) {
        (_, "B") => format!("{bytes} B"),
        (v, unit) if v >= 100.0 => format!("{v:.0} {unit}"),
        (v, unit) if v >= 10.0 => format!("{v:.1} {unit}"),
        (v, unit) => format!("{v:.2} {unit}"),
    }
}

/// `1536` → `1.5 KiB` (lives beside the unit loop so crates below this one print alike).
pub use motu_alloc::format_size;

/// `1.2M`, `15.3G`, `999`.
pub fn human_count(n: u64) -> String {
    const UNITS: [(&str, f64); 4] = [("T", 1e12), ("G", 1e9), ("M", 1e6), ("k", 1e3)];
    for (s, d) in UNITS {
        if n as f64 >= d {
            return format!("{:.1}{s}", n as f64 / d);
        }
    }
    n.to_string()
}
