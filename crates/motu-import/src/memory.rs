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

/// Scene text parsed between two heap trims while parsing ([`TrimEvery`]).
pub(crate) const TRIM_EVERY_BYTES: u64 = 256 << 20;

/// Trims the heap ([`release_free_heap`]) each time a byte count passes another multiple of
/// a step: the parser's threads free mesh arrays and parsed pieces of many sizes, and glibc
/// keeps the holes resident in their arenas, so without trims the resident set grows with
/// the scene's size even though what is live does not (island 0.05 → 0.1: the peak grows
/// ~60 MB while the heap left after a trim stays at ~150 MB).
pub(crate) struct TrimEvery {
    step_bytes: u64,
    next_bytes: std::sync::atomic::AtomicU64,
}

impl TrimEvery {
    pub(crate) fn new(step_bytes: u64) -> Self {
        Self {
            step_bytes: step_bytes.max(1),
            next_bytes: std::sync::atomic::AtomicU64::new(step_bytes.max(1)),
        }
    }

    /// Trims if `bytes` passed the next mark; returns whether it did.
    pub(crate) fn at(&self, bytes: u64) -> bool {
        use std::sync::atomic::Ordering;
        let next = self.next_bytes.load(Ordering::Relaxed);
        if bytes < next {
            return false;
        }
        let after = (bytes / self.step_bytes + 1).saturating_mul(self.step_bytes);
        // One caller trims per mark passed, whichever thread reports it.
        if self
            .next_bytes
            .compare_exchange(next, after, Ordering::Relaxed, Ordering::Relaxed)
            .is_err()
        {
            return false;
        }
        release_free_heap();
        true
    }
}

/// glibc malloc arenas `motu import` runs with ([`cap_malloc_arenas`]). glibc gives each new
/// thread its own arena up to 8 per core, and the import's pool threads allocate what other
/// threads free (PLY and parsed mesh arrays read on the pool, stored and cut elsewhere;
/// parsed pieces of included files, replayed and dropped on the parsing thread). The freed
/// blocks stay resident in their own thread's arena, and an arena's top is only handed back
/// when its free part passes glibc's trim threshold, which rises to 64 MiB once a large
/// block has been freed: at 16 threads island 0.05 peaked at 495–547 MB with the default
/// arenas against 392–436 MB with 4, island 0.1 at 632–656 against 445–501 MB (2-core box,
/// alternated, the same CPU time); island 0.63 on the 16-core host 1.42 GB against 1.16 GB in
/// one pair (`MALLOC_ARENA_MAX=4`; issue 48 item 1). The import makes only ~220,000 heap
/// allocations on island 0.05, so 16 threads sharing 4 arenas' locks rarely meet.
pub const IMPORT_MALLOC_ARENAS: usize = 4;

/// Caps the number of glibc malloc arenas for the rest of the process (`mallopt(M_ARENA_MAX)`).
/// Process-wide, so the binary calls it (`motu import`, before its thread pool starts: glibc
/// fixes its limit when the ninth arena is made). Does nothing and returns `false` where the
/// allocator is not glibc's, for 0, or when the user chose arenas themselves
/// (`MALLOC_ARENA_MAX`, or `arena_max` in `GLIBC_TUNABLES`).
pub fn cap_malloc_arenas(arenas: usize) -> bool {
    let chosen_by_user = std::env::var_os("MALLOC_ARENA_MAX").is_some()
        || std::env::var("GLIBC_TUNABLES").is_ok_and(|t| t.contains("arena_max"));
    if arenas == 0 || chosen_by_user {
        return false;
    }
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        let arenas = libc::c_int::try_from(arenas).unwrap_or(libc::c_int::MAX);
        // SAFETY: `mallopt` only sets one of glibc's malloc parameters under its own lock;
        // arenas made before the call stay valid (new threads then share existing ones).
        unsafe { libc::mallopt(libc::M_ARENA_MAX, arenas) == 1 }
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    false
}
