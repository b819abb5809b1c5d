//! A device's measured rates, kept in the cache directory beside its entries, so that a new
//! process decides restore against build from what the last one measured instead of a guess.
//!
//! Whether a cached structure is worth restoring depends on the device (its build rate), the
//! host (its upload rate) and the disk (its read rate): on lavapipe a restore is far cheaper
//! than a CPU build, on an H100 building 12.9 GB took 1.2 s where reading and restoring it took
//! 2.0 s (BENCHMARKS.md, session 50). The GPU layer fits those rates per process; this file
//! carries them to the next one.
//!
//! One small text file per device: `DIR/rates-v1/<xxh3 of the device identity>.txt`, the
//! identity inside it as well, each operation's fit on a line, and a checksum of the text
//! before it. Written atomically (temp file, rename). A missing, unreadable, corrupt or
//! foreign file (another device's, copied or renamed) is never an error: the caller warns and
//! starts from its priors.

use std::fs;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

use xxhash_rust::xxh3::xxh3_64;

use crate::file::create_private_dir_all;

/// The rates files' directory under the cache directory (apart from the entries' `v1/`, which
/// the scan at open reads; bump with the format).
pub const RATES_DIR: &str = "rates-v1";
const FIRST_LINE: &str = "motu device rates v1";

/// One operation's fit: `ms ≈ per_blas_ms + bytes / gb_per_s` per structure, from `batches`
/// batches.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rate {
    pub batches: u32,
    pub per_blas_ms: f64,
    /// GB/s; `f64::INFINITY`: no per-byte cost.
    pub gb_per_s: f64,
}

/// The rates a process measured on one device (`None`: not measured).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DeviceRates {
    /// Building a BLAS from its meshes (with compaction).
    pub build: Option<Rate>,
    /// Restoring one from a blob in host memory (upload and deserialise).
    pub restore: Option<Rate>,
    /// Reading a blob from the cache directory (what the frame's thread waited for).
    pub disk_read: Option<Rate>,
    /// Serialising one into a blob (size query, serialise copy, the host's copy).
    pub store: Option<Rate>,
}

impl DeviceRates {
    fn fields(&self) -> [(&'static str, Option<Rate>); 4] {
        [
            ("build", self.build),
            ("restore", self.restore),
            ("disk_read", self.disk_read),
            ("store", self.store),
        ]
    }

    fn field_mut(&mut self, name: &str) -> Option<&mut Option<Rate>> {
        match name {
            "build" => Some(&mut self.build),
            "restore" => Some(&mut self.restore),
            "disk_read" => Some(&mut self.disk_read),
            "store" => Some(&mut self.store),
            _ => None,
        }
    }
}

/// Why a rates file was not used.
#[derive(Debug, thiserror::Error)]
pub enum RatesError {
    #[error("no rates file")]
    Missing,
    #[error("unreadable rates file: {0}")]
    Io(#[from] io::Error),
    #[error("corrupt rates file: {0}")]
    Corrupt(&'static str),
    #[error("rates file of another device ({0:?})")]
    Foreign(String),
}

impl RatesError {
    /// `missing`, `unreadable`, `corrupt` or `foreign`, as `--stats` names it.
    pub fn name(&self) -> &'static str {
        match self {
            RatesError::Missing => "missing",
            RatesError::Io(_) => "unreadable",
            RatesError::Corrupt(_) => "corrupt",
            RatesError::Foreign(_) => "foreign",
        }
    }
}

/// Why a `--stream-rates` list ([`parse_rates`]) was refused.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum RatesSpecError {
    #[error("{0:?} is not OP=GB/S or OP=GB/S+MS (OP: build, restore, disk_read or store)")]
    Malformed(String),
    #[error("{0:?} names no operation: build, restore, disk_read or store")]
    UnknownOperation(String),
    #[error(
        "{0:?}: a rate is a number of GB/s above 0 (inf: no per-byte cost), the fixed part \
             milliseconds per structure, 0 or more"
    )]
    BadNumber(String),
    #[error("{0:?} is named twice")]
    Twice(String),
}

/// Rates written by hand (`motu render --stream-rates`), comma-separated `OP=GB/S` or
/// `OP=GB/S+MS` with OP one of `build`, `restore`, `disk_read`, `store`, GB/S the rate (GB of
/// structure a second; `inf`: no per-byte cost) and MS a fixed milliseconds per structure:
/// `build=0.5,restore=4+0.1`. An operation not named stays `None`; `batches` is 0 (none
/// measured).
pub fn parse_rates(spec: &str) -> Result<DeviceRates, RatesSpecError> {
    let mut rates = DeviceRates::default();
    for item in spec.split(',').map(str::trim) {
        let (name, value) = item
            .split_once('=')
            .ok_or_else(|| RatesSpecError::Malformed(item.into()))?;
        let name = name.trim();
        let slot = rates
            .field_mut(name)
            .ok_or_else(|| RatesSpecError::UnknownOperation(name.into()))?;
        if slot.is_some() {
            return Err(RatesSpecError::Twice(name.into()));
        }
        let (gb, ms) = value.split_once('+').unwrap_or((value, "0"));
        let bad = || RatesSpecError::BadNumber(item.into());
        let gb_per_s: f64 = gb.trim().parse().map_err(|_| bad())?;
        let per_blas_ms: f64 = ms.trim().parse().map_err(|_| bad())?;
        // As `decode_rates` accepts them: a rate of 0 would divide by zero.
        if gb_per_s.is_nan() || gb_per_s <= 0.0 || !per_blas_ms.is_finite() || per_blas_ms < 0.0 {
            return Err(bad());
        }
        *slot = Some(Rate {
            batches: 0,
            per_blas_ms,
            gb_per_s,
        });
    }
    Ok(rates)
}

/// `device` on one line (an identity with line breaks would otherwise split the file).
fn one_line(device: &str) -> String {
    device.replace(['\n', '\r'], " ")
}

/// The rates file of `device` under cache directory `root`.
pub fn rates_path(root: &Path, device: &str) -> PathBuf {
    let id = xxh3_64(one_line(device).as_bytes());
    root.join(RATES_DIR).join(format!("{id:016x}.txt"))
}

/// The file's text for `device`'s `rates`.
pub fn encode_rates(device: &str, rates: &DeviceRates) -> String {
    let mut text = format!("{FIRST_LINE}\ndevice {}\n", one_line(device));
    for (name, rate) in rates.fields() {
        if let Some(r) = rate {
            text += &format!("{name} {} {} {}\n", r.batches, r.per_blas_ms, r.gb_per_s);
        }
    }
    let sum = xxh3_64(text.as_bytes());
    text + &format!("checksum {sum:016x}\n")
}

/// The rates in `text` when it is a whole, unchanged file written for `device`.
pub fn decode_rates(text: &str, device: &str) -> Result<DeviceRates, RatesError> {
    let corrupt = RatesError::Corrupt;
    let body_end = text
        .trim_end_matches('\n')
        .rfind('\n')
        .map(|i| i + 1)
        .ok_or(corrupt("too short"))?;
    let (body, last) = text.split_at(body_end);
    let stored = last
        .trim_end()
        .strip_prefix("checksum ")
        .and_then(|h| u64::from_str_radix(h, 16).ok())
        .ok_or(corrupt("no checksum line"))?;
    if stored != xxh3_64(body.as_bytes()) {
        return Err(corrupt("checksum mismatch"));
    }
    let mut lines = body.lines();
    if lines.next() != Some(FIRST_LINE) {
        return Err(corrupt("not a rates file of this version"));
    }
    let written_for = lines
        .next()
        .and_then(|l| l.strip_prefix("device "))
        .ok_or(corrupt("no device line"))?;
    if written_for != one_line(device) {
        return Err(RatesError::Foreign(written_for.to_string()));
    }
    let mut rates = DeviceRates::default();
    for line in lines {
        let mut words = line.split(' ');
        let slot = words
            .next()
            .and_then(|name| rates.field_mut(name))
            .ok_or(corrupt("an unknown operation"))?;
        let batches = words.next().and_then(|w| w.parse::<u32>().ok());
        let per_blas_ms = words.next().and_then(|w| w.parse::<f64>().ok());
        let gb_per_s = words.next().and_then(|w| w.parse::<f64>().ok());
        match (batches, per_blas_ms, gb_per_s, words.next()) {
            (Some(batches), Some(ms), Some(gb), None)
                if ms.is_finite() && ms >= 0.0 && gb > 0.0 && !gb.is_nan() =>
            {
                *slot = Some(Rate {
                    batches,
                    per_blas_ms: ms,
                    gb_per_s: gb,
                });
            }
            _ => return Err(corrupt("a malformed rate")),
        }
    }
    Ok(rates)
}

/// `device`'s rates from the file under `root`.
pub fn load_rates(root: &Path, device: &str) -> Result<DeviceRates, RatesError> {
    let text = match fs::read(rates_path(root, device)) {
        Ok(bytes) => String::from_utf8(bytes).map_err(|_| RatesError::Corrupt("not text"))?,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Err(RatesError::Missing),
        Err(e) => return Err(e.into()),
    };
    decode_rates(&text, device)
}

/// Writes `device`'s `rates` under `root`, atomically (temp file, rename over the name).
pub fn save_rates(root: &Path, device: &str, rates: &DeviceRates) -> io::Result<()> {
    let path = rates_path(root, device);
    let dir = root.join(RATES_DIR);
    create_private_dir_all(&dir)?;
    let mut temp = tempfile::Builder::new()
        .prefix(".rates-")
        .tempfile_in(&dir)?;
    temp.write_all(encode_rates(device, rates).as_bytes())?;
    temp.persist(&path).map_err(|e| e.error)?;
    Ok(())
}

#[cfg(test)]
mod tests;
