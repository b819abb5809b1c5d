//! The process's own memory use, for logs and summaries (imports must stream: peak RSS is
//! reported so a run shows it stayed near the instance skeleton).

/// Peak resident memory of this process so far (Linux `VmHWM`), if known.
pub fn peak_rss_bytes() -> Option<u64> {
    status_kib("VmHWM:").map(|k| k * 1024)
}

/// Resident memory of this process now (Linux `VmRSS`), if known.
pub fn rss_bytes() -> Option<u64> {
    status_kib("VmRSS:").map(|k| k * 1024)
}

fn status_kib(key: &str) -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with(key))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

/// Logs (debug) the resident and peak resident memory at the end of an import phase: where
/// the peak is reached, by phase (`RUST_LOG=motu_import=debug`).
pub(crate) fn log_phase(phase: &'static str) {
    if tracing::enabled!(tracing::Level::DEBUG) {
        tracing::debug!(
            phase,
            rss_bytes = rss_bytes().unwrap_or(0),
            peak_rss_bytes = peak_rss_bytes().unwrap_or(0),
            "memory at phase end"
        );
    }
}
