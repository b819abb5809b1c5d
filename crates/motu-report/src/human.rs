//! Byte sizes and counts for people (`1.50 GiB`, `15.3G`), shared by every output format.

/// `1.50 GiB`, `12.0 MiB`, `640 B`.
pub fn human_bytes(bytes: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut v = bytes as f64;
    let mut u = 0;
    while v >= 1024.0 && u + 1 < UNITS.len() {
        v /= 1024.0;
        u += 1;
    }
    match u {
        0 => format!("{bytes} B"),
        _ if v >= 100.0 => format!("{v:.0} {}", UNITS[u]),
        _ if v >= 10.0 => format!("{v:.1} {}", UNITS[u]),
        _ => format!("{v:.2} {}", UNITS[u]),
    }
}

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
