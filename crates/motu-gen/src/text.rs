//! Output files and fast, deterministic number formatting.
//!
//! Numbers are written with a fixed number of decimals and trailing zeros
//! trimmed: integer arithmetic only after one rounding, so formatting is a
//! few ns per number and identical on every run.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::GenError;

const POW10: [f64; 10] = [1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9];
const POW10_U64: [u64; 10] = [
    1,
    10,
    100,
    1_000,
    10_000,
    100_000,
    1_000_000,
    10_000_000,
    100_000_000,
    1_000_000_000,
];

/// Appends the decimal digits of `n`.
pub(crate) fn push_u64(out: &mut Vec<u8>, mut n: u64) {
    let mut digits = [0u8; 20];
    let mut i = digits.len();
    loop {
        i -= 1;
        digits[i] = b'0' + (n % 10) as u8;
        n /= 10;
        if n == 0 {
            break;
        }
    }
    out.extend_from_slice(&digits[i..]);
}

/// Appends `x` rounded to `decimals` (≤ 9) decimals, trailing zeros trimmed,
/// never `-0`. Non-finite values (never produced by the generators) print as 0.
pub(crate) fn push_fixed(out: &mut Vec<u8>, x: f64, decimals: u32) {
    let d = decimals.min(9) as usize;
    if !x.is_finite() {
        out.push(b'0');
        return;
    }
    let scaled = (x * POW10[d]).round();
    if scaled.abs() >= 9.0e18 {
        // Beyond i64: rare enough for the slow path.
        let _ = write!(out, "{x:.0}");
        return;
    }
    let mut n = scaled as i64;
    if n == 0 {
        out.push(b'0');
        return;
    }
    if n < 0 {
        out.push(b'-');
        n = -n;
    }
    let n = n as u64;
    push_u64(out, n / POW10_U64[d]);
    let mut frac = n % POW10_U64[d];
    if frac != 0 {
        let mut width = d;
        while frac % 10 == 0 {
            frac /= 10;
            width -= 1;
        }
        out.push(b'.');
        let start = out.len();
        out.resize(start + width, b'0');
        let mut i = start + width;
        while frac > 0 {
            i -= 1;
            out[i] = b'0' + (frac % 10) as u8;
            frac /= 10;
        }
    }
}

/// Live totals shared by all writer threads, read by the progress reporter.
#[derive(Debug, Default)]
pub(crate) struct LiveCounters {
    pub(crate) bytes: AtomicU64,
    pub(crate) files: AtomicU64,
}

/// Flush the thread-local byte count to the shared counter this often.
const LIVE_FLUSH_BYTES: u64 = 4 << 20;

/// One output file: buffered, byte-counted, errors carry the path.
pub(crate) struct OutFile<'a> {
    path: PathBuf,
    writer: BufWriter<File>,
    size_bytes: u64,
    unreported_bytes: u64,
    live: &'a LiveCounters,
}

impl<'a> OutFile<'a> {
    /// Creates `root/relative` (and its parent folders).
    pub(crate) fn create(
        root: &Path,
        relative: &str,
        live: &'a LiveCounters,
    ) -> Result<Self, GenError> {
        let path = root.join(relative);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(|source| GenError::Io {
                path: parent.to_path_buf(),
                source,
            })?;
        }
        let file = File::create(&path).map_err(|source| GenError::Io {
            path: path.clone(),
            source,
        })?;
        Ok(Self {
            path,
            writer: BufWriter::with_capacity(1 << 20, file),
            size_bytes: 0,
            unreported_bytes: 0,
            live,
        })
    }

    pub(crate) fn write(&mut self, bytes: &[u8]) -> Result<(), GenError> {
        self.writer
            .write_all(bytes)
            .map_err(|source| GenError::Io {
                path: self.path.clone(),
                source,
            })?;
        let n = bytes.len() as u64;
        self.size_bytes += n;
        self.unreported_bytes += n;
        if self.unreported_bytes >= LIVE_FLUSH_BYTES {
            self.live
                .bytes
                .fetch_add(self.unreported_bytes, Ordering::Relaxed);
            self.unreported_bytes = 0;
        }
        Ok(())
    }

    pub(crate) fn write_str(&mut self, s: &str) -> Result<(), GenError> {
        self.write(s.as_bytes())
    }

    /// Writes `line` and clears it (the caller reuses the allocation).
    pub(crate) fn drain(&mut self, line: &mut Vec<u8>) -> Result<(), GenError> {
        self.write(line)?;
        line.clear();
        Ok(())
    }

    /// Flushes and returns the file's size in bytes.
    pub(crate) fn finish(mut self) -> Result<u64, GenError> {
        self.writer.flush().map_err(|source| GenError::Io {
            path: self.path.clone(),
            source,
        })?;
        self.live
            .bytes
            .fetch_add(self.unreported_bytes, Ordering::Relaxed);
        self.live.files.fetch_add(1, Ordering::Relaxed);
        Ok(self.size_bytes)
    }
}

#[cfg(test)]
mod tests;
