//! Human sizes on the command line: `64MiB`, `8GiB`, `1.5GB`, plain bytes.

/// A VRAM budget: a size of at least one byte (0 holds nothing; said here with the option's
/// words, not the allocator's field name).
pub fn parse_budget(s: &str) -> Result<u64, String> {
    match parse_size(s)? {
        0 => Err(format!(
            "'{s}': a budget of 0 bytes holds nothing; give a size such as 512MiB (or leave the option out for the device's own budget)"
        )),
        b => Ok(b),
    }
}

/// Parses a size in bytes. Binary (`KiB`, `MiB`, `GiB`, `TiB`) and decimal (`KB`, `MB`, `GB`,
/// `TB`) suffixes, case-insensitive; `K`/`M`/`G`/`T` alone are binary.
pub fn parse_size(s: &str) -> Result<u64, String> {
    let t = s.trim();
    let split = t
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(t.len());
    let (num, unit) = t.split_at(split);
    if num.is_empty() {
        return Err(format!(
            "'{s}' is not a size (expected e.g. 64MiB, 8GiB or 1048576)"
        ));
    }
    let mult: u64 = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1,
        "k" | "kib" => 1 << 10,
        "m" | "mib" => 1 << 20,
        "g" | "gib" => 1 << 30,
        "t" | "tib" => 1 << 40,
        "kb" => 1_000,
        "mb" => 1_000_000,
        "gb" => 1_000_000_000,
        "tb" => 1_000_000_000_000,
        other => {
            return Err(format!(
                "unknown size unit '{other}' in '{s}' (use B, KiB, MiB, GiB, TiB, KB, MB, GB, TB)"
            ))
        }
    };
    if num.contains('.') {
        let v: f64 = num.parse().map_err(|_| format!("'{s}' is not a size"))?;
        let bytes = v * mult as f64;
        if !(0.0..1.8e19).contains(&bytes) {
            return Err(format!("'{s}' is out of range"));
        }
        Ok(bytes.round() as u64)
    } else {
        let v: u64 = num.parse().map_err(|_| format!("'{s}' is not a size"))?;
        v.checked_mul(mult)
            .ok_or_else(|| format!("'{s}' is out of range"))
    }
}

/// `1536` → `1.5 KiB` (lives in motu-report so that `motu-bench` prints the same sizes).
pub use motu_report::format_size;

#[cfg(test)]
mod tests;
