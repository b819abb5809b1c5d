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
/// The resident set's anonymous (heap) and file-backed (mapped scene text, edge files) parts
/// are logged apart.
pub(crate) fn log_phase(phase: &'static str) {
    if tracing::enabled!(tracing::Level::DEBUG) {
        let kib = |key| status_kib(key).map_or(0, |k| k * 1024);
        tracing::debug!(
            phase,
            rss_bytes = rss_bytes().unwrap_or(0),
            peak_rss_bytes = peak_rss_bytes().unwrap_or(0),
            anon_bytes = kib("RssAnon:"),
            file_bytes = kib("RssFile:"),
            "memory at phase end"
        );
    }
}

/// Hands the heap's free pages back to the system (glibc's `malloc_trim`; nothing elsewhere).
/// The parser's threads each allocate from their own arena, and what they free (text windows,
/// buffered events, mesh arrays on their way to the package) stays resident in those arenas
/// unless trimmed: on island 0.1 ~200 MB of the resident set after parsing, beside which the
/// compiler's instance table then grew (issue 48 item 1).
pub(crate) fn release_free_heap() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        // SAFETY: `malloc_trim` only returns free memory of glibc's arenas to the system; it
        // takes each arena's lock and touches no live allocation.
        unsafe {
            libc::malloc_trim(0);
        }
    }
}
