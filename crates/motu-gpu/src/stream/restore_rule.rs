//! Which cached BLASes are restored rather than built, and which built BLASes are written to
//! the cache directory, by this device's measured rates (issue 45.3).
//!
//! A cache may make a process slower: on an H100 (island 0.63 at 24 GiB, nothing evicted)
//! the warm process restored 12.9 GB in 2.0 s (disk read 1.0, upload 0.66, deserialise 0.41)
//! where building the same BLASes took 1.2 s, so it reached its image 1.6 s after the
//! uncached one (BENCHMARKS.md, session 50); on lavapipe a restore is far cheaper than a CPU
//! build. So the decision is per device, from fits as the host tier's store rule makes them
//! (`store_policy.rs`: `ms(S) = per_blas_ms + S / rate` per structure of `S` bytes):
//!
//! - a cached BLAS found in **host memory** is restored when `restore(S) ≤ build(S)`;
//! - one found only **in the directory** when `disk_read(S) + restore(S) ≤ build(S)`;
//! - a built BLAS is **written to the directory** only when that restore would pay in the next
//!   process (the disk comparison); one that would not is left to the host tier's own rule
//!   (kept in host memory only, where its restores in this process pay: the 8 GiB case, where
//!   evicted BLASes come back), or not stored at all.
//!
//! `restore` is the upload and deserialise copies, `disk_read` what the frame's thread waited
//! for the entries (reads run beside the group's mesh uploads, `cache/reads.rs`, so only what
//! outlasts them counts), `build` the builds with compaction. Each rate is this process's fit
//! once it has [`MIN_BATCHES`](super::store_policy::MIN_BATCHES) batches, else the one the
//! cache directory's rates file recorded for this device (`motu_ascache::rates`; this process
//! writes its own back at the end), else **unknown**: a decision with an unknown rate restores
//! and writes, as before the rule, so that the rates get measured (a cold process writes what
//! it builds; the next one restores until its own fits replace the file's). A decision changes
//! only whether a BLAS is restored or built, never what is traced: a restored structure is the
//! one that was built.
//!
//! **Fixed rates** (`--stream-rates`, [`StreamOptions::fixed_rates`](super::StreamOptions::fixed_rates)):
//! the rule, and the host tier's store rule, decide from the given rates alone, never from
//! this process's fits or the rates file (neither read nor written), and an operation not
//! given stays unknown (the store rule: its prior). Measured rates follow this machine's load
//! and timing, so counts (BLASes built or restored, what stays resident) may differ between
//! two runs of the same command; with fixed rates the decisions depend only on sizes and
//! counts, the same on every run and machine (tests, comparisons between machines).

use motu_ascache::{DeviceRates, Rate, RatesError, Tier};

use super::store_policy::{Cost, CostFit, Prior, StoreEstimator, StorePolicyStats, PRIOR};

/// The rates the restore rule decides from beside [`StoreEstimator`]'s (see the module docs).
#[derive(Clone, Debug)]
pub(super) struct RestoreRule {
    /// What the cache directory's rates file held at the start (nothing when it had none).
    file: DeviceRates,
    file_state: &'static str,
    /// Reads of entries from the directory: waited milliseconds per batch.
    pub disk_read: CostFit,
    saved: bool,
    /// `file` holds fixed rates (`--stream-rates`): no fit replaces them.
    fixed: bool,
}

impl Default for RestoreRule {
    fn default() -> Self {
        RestoreRule {
            file: DeviceRates::default(),
            file_state: "none",
            disk_read: CostFit::default(),
            saved: false,
            fixed: false,
        }
    }
}

fn cost(rate: Option<Rate>) -> Option<Cost> {
    rate.map(|r| Cost {
        per_blas_ms: r.per_blas_ms,
        gb_per_s: r.gb_per_s,
    })
}

/// `fit` as a rate to record: its own once measured, else what the file had.
fn record(fit: &CostFit, file: Option<Rate>) -> Option<Rate> {
    match fit.measured() {
        Some(c) => Some(Rate {
            batches: fit.batches(),
            per_blas_ms: c.per_blas_ms,
            gb_per_s: c.gb_per_s,
        }),
        None => file,
    }
}

impl RestoreRule {
    /// The rule with the rates file's `loaded` rates (or why there were none).
    pub(super) fn from_file(loaded: Result<DeviceRates, RatesError>) -> RestoreRule {
        let (file, file_state) = match loaded {
            Ok(rates) => (rates, "loaded"),
            Err(e) => (DeviceRates::default(), e.name()),
        };
        RestoreRule {
            file,
            file_state,
            ..RestoreRule::default()
        }
    }

    /// The rule deciding from `rates` alone (`--stream-rates`; see the module docs): reported
    /// as rates file `fixed`.
    pub(super) fn fixed(rates: DeviceRates) -> RestoreRule {
        RestoreRule {
            file: rates,
            file_state: "fixed",
            fixed: true,
            ..RestoreRule::default()
        }
    }

    /// Whether the rates are fixed (`--stream-rates`): no rates file is read or written.
    pub(super) fn is_fixed(&self) -> bool {
        self.fixed
    }

    /// The host tier's priors: the file's (or the fixed) rates where it has them, else
    /// [`PRIOR`].
    pub(super) fn prior(&self) -> Prior {
        Prior {
            build: cost(self.file.build).unwrap_or(PRIOR.build),
            restore: cost(self.file.restore).unwrap_or(PRIOR.restore),
            store: cost(self.file.store).unwrap_or(PRIOR.store),
            ..PRIOR
        }
    }

    /// This process's fit of `fit`, else the file's `rate`, else `None` (unknown); with
    /// fixed rates, `rate` alone.
    fn known(&self, fit: &CostFit, rate: Option<Rate>) -> Option<Cost> {
        if self.fixed {
            return cost(rate);
        }
        fit.measured().or(cost(rate))
    }

    /// Whether a cached BLAS of `bytes` held by `tier` is restored rather than built.
    pub(super) fn restore_pays(&self, est: &StoreEstimator, bytes: u64, tier: Tier) -> bool {
        let build = self.known(&est.build, self.file.build);
        let restore = self.known(&est.restore, self.file.restore);
        let read = match tier {
            Tier::Host => Some(Cost {
                per_blas_ms: 0.0,
                gb_per_s: f64::INFINITY,
            }),
            Tier::Disk => self.known(&self.disk_read, self.file.disk_read),
        };
        match (build, restore, read) {
            (Some(build), Some(restore), Some(read)) => {
                read.ms(bytes) + restore.ms(bytes) <= build.ms(bytes)
            }
            // Unknown: restore, and so measure it.
            _ => true,
        }
    }

    /// Whether a built BLAS of `bytes` is written to the cache directory: its restore from
    /// there would pay in the next process.
    pub(super) fn write_pays(&self, est: &StoreEstimator, bytes: u64) -> bool {
        self.restore_pays(est, bytes, Tier::Disk)
    }

    /// The rates to record for the next process: each measured one, else the file's.
    pub(super) fn to_save(&self, est: &StoreEstimator) -> DeviceRates {
        DeviceRates {
            build: record(&est.build, self.file.build),
            restore: record(&est.restore, self.file.restore),
            disk_read: record(&self.disk_read, self.file.disk_read),
            store: record(&est.store, self.file.store),
        }
    }

    pub(super) fn note_saved(&mut self) {
        self.saved = true;
    }

    /// `st` with the rule's disk reads and rates file.
    pub(super) fn add_stats(&self, st: &mut StorePolicyStats) {
        let read = self.known(&self.disk_read, self.file.disk_read);
        let finite = |v: f64| if v.is_finite() { v } else { 0.0 };
        st.disk_read_batches = self.disk_read.batches();
        st.disk_read_ms_per_blas = read.map_or(0.0, |c| c.per_blas_ms);
        st.disk_read_gb_per_s = read.map_or(0.0, |c| finite(c.gb_per_s));
        st.disk_read_mean_gb_per_s = self.disk_read.mean_gb_per_s();
        st.rates_file = self.file_state;
        st.rates_saved = self.saved;
    }
}

#[cfg(test)]
mod tests;
