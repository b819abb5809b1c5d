//! Which built BLASes the serialised host tier stores (`--stream-host-cache-policy`).
//!
//! Storing a BLAS for its return costs a serialise copy and the host's copy out of the
//! readback buffer *now*; it pays only if the BLAS comes back and restoring it is cheaper
//! than building it again from its meshes. On lavapipe (CPU builds) a restore is far cheaper
//! than a build, so storing pays; on an H100 (island 0.3 at a quarter, meshes in host memory,
//! `--no-as-cache`) restoring ran at ~2.7 GB/s, rebuilding at ~2.9 GB/s, and the stores cost
//! ~118 ms a frame (281 MB serialised, 22 of 100 structures back in that frame): `--host-cache
//! 0` was faster (BENCHMARKS.md, session 37).
//!
//! **The rule** (`measured`, the default): a BLAS of `S` structure bytes is stored when
//!
//! `returns × (build_ms(S) − restore_ms(S)) > store_ms(S)`
//!
//! where each `*_ms(S) = per_blas_ms + S / rate` is a least-squares fit of this process's own
//! batches of that operation (builds: `build_blas_set` with compaction; restores: the staging
//! copies and the device's deserialise copies, disk reads excluded; stores: size queries,
//! serialise copies, the host's copies and the hand-over to the cache), so small structures
//! pay their fixed costs; and `returns` is how often a built structure has come back in this
//! process so far (restored or rebuilt after an eviction, per distinct BLAS built), counted
//! apart for BLASes that have already returned once (they return again more often). So a
//! restore not faster than a rebuild stores nothing, and small structures whose rebuild is
//! cheaper than store plus restore are not stored. Until an operation has
//! [`MIN_BATCHES`] batches (or [`MIN_BLASES`] BLASes were built, for `returns`) its estimate
//! is the prior [`PRIOR`]: the H100's rates above, which store nothing until this device's
//! builds measure slower than its restores.
//!
//! The policy decides only what the *host tier alone* would keep. A BLAS written to a
//! writable cache directory (for the next process, where its restore there would pay:
//! `restore_rule.rs`) is stored whatever this rule says (the write-through needs the
//! serialised copy anyway, and the host tier then keeps the same blob at no extra cost); a
//! host tier of 0 bytes stores nothing for the host; `always` stores every BLAS built (the
//! behaviour before the policy). The priors below give way to the rates the cache directory
//! recorded for this device, where it has them. Skipped stores are counted (`host_cache_skipped_stores`) and
//! the estimates reported (`stream.totals.store_policy`).

/// Which built BLASes the serialised host tier stores (`--stream-host-cache-policy`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum HostStorePolicy {
    /// Those whose expected restores save more than their store costs (the module docs).
    #[default]
    Measured,
    /// Every BLAS built, written to a cache directory too, and every cached BLAS restored
    /// (the behaviour before the policy and the restore rule, `restore_rule.rs`).
    Always,
}

impl HostStorePolicy {
    pub fn name(self) -> &'static str {
        match self {
            HostStorePolicy::Measured => "measured",
            HostStorePolicy::Always => "always",
        }
    }
}

/// Batches of an operation before its own fit replaces the prior.
pub(super) const MIN_BATCHES: u32 = 3;
/// Distinct BLASes built before the measured return rate replaces the prior (and BLASes
/// returned, for the rate of those that returned before).
pub(super) const MIN_BLASES: u64 = 32;
pub(super) const MIN_RETURNED: u64 = 8;

/// An operation's cost per structure: a fixed part and a rate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Cost {
    pub per_blas_ms: f64,
    /// Structure bytes per second, in GB/s (`f64::INFINITY`: no per-byte cost).
    pub gb_per_s: f64,
}

impl Cost {
    const fn rate(gb_per_s: f64) -> Cost {
        Cost {
            per_blas_ms: 0.0,
            gb_per_s,
        }
    }

    /// Milliseconds for one structure of `bytes`.
    pub(super) fn ms(&self, bytes: u64) -> f64 {
        self.per_blas_ms + bytes as f64 / (self.gb_per_s * 1e6)
    }
}

/// The estimates before this process measured its own.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Prior {
    pub build: Cost,
    pub restore: Cost,
    pub store: Cost,
    /// Returns per BLAS built, and per BLAS that returned before.
    pub returns_fresh: f64,
    pub returns_again: f64,
}

/// The H100's measured rates (island 0.3 at a quarter, BENCHMARKS.md session 37): builds
/// ~2.9 GB/s, restores ~2.7 GB/s, stores 281 MB in ~118 ms (~2.4 GB/s); returns a guess of one
/// per structure (at most the rule's deciding factor where rates say restores are cheaper).
pub(super) const PRIOR: Prior = Prior {
    build: Cost::rate(2.9),
    restore: Cost::rate(2.7),
    store: Cost::rate(2.4),
    returns_fresh: 1.0,
    returns_again: 1.0,
};

/// A running least-squares fit of batch times: `ms ≈ per_blas_ms × n + gb / rate`.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct CostFit {
    batches: u32,
    bytes: u64,
    ms: f64,
    // Sums of products over batches, x = (n, GB), y = ms.
    snn: f64,
    sng: f64,
    sgg: f64,
    sny: f64,
    sgy: f64,
}

impl CostFit {
    /// A batch of `blases` structures, `bytes` together, took `ms`.
    pub(super) fn add(&mut self, blases: u64, bytes: u64, ms: f64) {
        if blases == 0 || !ms.is_finite() || ms < 0.0 {
            return;
        }
        let n = blases as f64;
        let g = bytes as f64 / 1e9;
        self.batches += 1;
        self.bytes += bytes;
        self.ms += ms;
        self.snn += n * n;
        self.sng += n * g;
        self.sgg += g * g;
        self.sny += n * ms;
        self.sgy += g * ms;
    }

    /// The fit, or `prior` with fewer than [`MIN_BATCHES`] batches. Coefficients are kept
    /// non-negative; batches of one shape (the same bytes per structure) fit a rate alone.
    pub(super) fn cost(&self, prior: Cost) -> Cost {
        if self.batches < MIN_BATCHES {
            return prior;
        }
        let rate_only = || {
            if self.sgg > 0.0 && self.sgy > 0.0 {
                Cost::rate(self.sgg / self.sgy * 1e3)
            } else {
                Cost::rate(f64::INFINITY)
            }
        };
        let fixed_only = || Cost {
            per_blas_ms: (self.sny / self.snn).max(0.0),
            gb_per_s: f64::INFINITY,
        };
        let det = self.snn * self.sgg - self.sng * self.sng;
        if det <= 1e-9 * self.snn * self.sgg {
            return rate_only();
        }
        let a = (self.sny * self.sgg - self.sng * self.sgy) / det;
        let ms_per_gb = (self.snn * self.sgy - self.sng * self.sny) / det;
        match (a >= 0.0, ms_per_gb > 0.0) {
            (true, true) => Cost {
                per_blas_ms: a,
                gb_per_s: 1e3 / ms_per_gb,
            },
            (false, _) => rate_only(),
            (true, false) => fixed_only(),
        }
    }

    /// The fit once it has [`MIN_BATCHES`] batches (`None` before: not measured here).
    pub(super) fn measured(&self) -> Option<Cost> {
        (self.batches >= MIN_BATCHES).then(|| self.cost(Cost::rate(f64::INFINITY)))
    }

    pub(super) fn batches(&self) -> u32 {
        self.batches
    }

    /// Bytes over milliseconds of every batch (GB/s; 0 with none).
    pub(super) fn mean_gb_per_s(&self) -> f64 {
        if self.ms > 0.0 {
            self.bytes as f64 / (self.ms * 1e6)
        } else {
            0.0
        }
    }
}

/// What the rule measures and decides from (see the module docs).
#[derive(Clone, Debug)]
pub(super) struct StoreEstimator {
    prior: Prior,
    /// Decide from `prior` whatever is measured (`--stream-rates`, `restore_rule.rs`); the
    /// fits are still made and reported.
    fixed: bool,
    pub build: CostFit,
    pub restore: CostFit,
    pub store: CostFit,
    /// Per BLAS: built (or restored) before; returned before.
    built: Vec<bool>,
    returned: Vec<bool>,
    /// Distinct BLASes built; returns; BLASes that returned; returns of those after their
    /// first.
    built_blases: u64,
    returns: u64,
    returned_blases: u64,
    returns_again: u64,
}

impl StoreEstimator {
    pub(super) fn new(blases: usize, prior: Prior) -> StoreEstimator {
        StoreEstimator {
            prior,
            fixed: false,
            build: CostFit::default(),
            restore: CostFit::default(),
            store: CostFit::default(),
            built: vec![false; blases],
            returned: vec![false; blases],
            built_blases: 0,
            returns: 0,
            returned_blases: 0,
            returns_again: 0,
        }
    }

    /// Decides from `prior` until this process measured its own rates (the rates file's,
    /// `restore_rule.rs`).
    pub(super) fn set_prior(&mut self, prior: Prior) {
        self.prior = prior;
    }

    /// Decides from `prior` alone from now on, whatever this process measures (fixed rates,
    /// `--stream-rates`: the same decisions on every run).
    pub(super) fn fix_prior(&mut self, prior: Prior) {
        self.prior = prior;
        self.fixed = true;
    }

    /// BLAS `b` was just built or restored: returns whether it had been before (a return).
    pub(super) fn note_made(&mut self, b: usize) -> bool {
        if !std::mem::replace(&mut self.built[b], true) {
            self.built_blases += 1;
            return false;
        }
        self.returns += 1;
        if std::mem::replace(&mut self.returned[b], true) {
            self.returns_again += 1;
        } else {
            self.returned_blases += 1;
        }
        true
    }

    /// Whether BLAS `b` has come back before.
    pub(super) fn returned_before(&self, b: usize) -> bool {
        self.returned.get(b).copied().unwrap_or(false)
    }

    /// Expected returns of a BLAS just built (`again`: one that returned before).
    pub(super) fn expected_returns(&self, again: bool) -> f64 {
        if again {
            if self.returned_blases < MIN_RETURNED {
                self.prior.returns_again
            } else {
                self.returns_again as f64 / self.returned_blases as f64
            }
        } else if self.built_blases < MIN_BLASES {
            self.prior.returns_fresh
        } else {
            self.returns as f64 / self.built_blases as f64
        }
    }

    pub(super) fn costs(&self) -> (Cost, Cost, Cost) {
        if self.fixed {
            return (self.prior.build, self.prior.restore, self.prior.store);
        }
        (
            self.build.cost(self.prior.build),
            self.restore.cost(self.prior.restore),
            self.store.cost(self.prior.store),
        )
    }

    /// The rule: whether storing a BLAS of `bytes` (`again`: it returned before) saves more
    /// than it costs.
    pub(super) fn should_store(&self, bytes: u64, again: bool) -> bool {
        let (build, restore, store) = self.costs();
        let saved = build.ms(bytes) - restore.ms(bytes);
        saved > 0.0 && self.expected_returns(again) * saved > store.ms(bytes)
    }

    /// The estimates as `--stats` reports them.
    pub(super) fn stats(&self, policy: HostStorePolicy) -> StorePolicyStats {
        let (build, restore, store) = self.costs();
        let finite = |v: f64| if v.is_finite() { v } else { 0.0 };
        StorePolicyStats {
            policy: policy.name(),
            build_batches: self.build.batches,
            build_ms_per_blas: build.per_blas_ms,
            build_gb_per_s: finite(build.gb_per_s),
            build_mean_gb_per_s: self.build.mean_gb_per_s(),
            restore_batches: self.restore.batches,
            restore_ms_per_blas: restore.per_blas_ms,
            restore_gb_per_s: finite(restore.gb_per_s),
            restore_mean_gb_per_s: self.restore.mean_gb_per_s(),
            store_batches: self.store.batches,
            store_ms_per_blas: store.per_blas_ms,
            store_gb_per_s: finite(store.gb_per_s),
            store_mean_gb_per_s: self.store.mean_gb_per_s(),
            built_blases: self.built_blases,
            returns: self.returns,
            returned_blases: self.returned_blases,
            returns_per_blas: self.expected_returns(false),
            returns_after_return: self.expected_returns(true),
            ..StorePolicyStats::default()
        }
    }
}

/// The host tier's store rule and its estimates at the end of the run (`stream.totals.
/// store_policy` in `--stats`): per operation its batches, the fit's fixed milliseconds per
/// BLAS and rate (the prior's while the batches are fewer than 3; a rate of 0: no per-byte
/// cost), and its plain mean rate; distinct BLASes built, returns (restored or rebuilt after
/// an eviction), BLASes that returned, and the expected returns the rule used.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StorePolicyStats {
    /// `measured` or `always` (`--stream-host-cache-policy`).
    pub policy: &'static str,
    pub build_batches: u32,
    pub build_ms_per_blas: f64,
    pub build_gb_per_s: f64,
    pub build_mean_gb_per_s: f64,
    pub restore_batches: u32,
    pub restore_ms_per_blas: f64,
    pub restore_gb_per_s: f64,
    pub restore_mean_gb_per_s: f64,
    pub store_batches: u32,
    pub store_ms_per_blas: f64,
    pub store_gb_per_s: f64,
    pub store_mean_gb_per_s: f64,
    pub built_blases: u64,
    pub returns: u64,
    pub returned_blases: u64,
    pub returns_per_blas: f64,
    pub returns_after_return: f64,
    /// The restore rule's own rate (`restore_rule.rs`): reading an entry from the cache
    /// directory (what the frame's thread waited for), as the others; 0s while unknown.
    pub disk_read_batches: u32,
    pub disk_read_ms_per_blas: f64,
    pub disk_read_gb_per_s: f64,
    pub disk_read_mean_gb_per_s: f64,
    /// The cache directory's rates file at the start: `loaded`, `missing`, `corrupt`,
    /// `foreign`, `unreadable`, or `none` (no cache directory); and whether this run wrote
    /// its rates there for the next process.
    pub rates_file: &'static str,
    pub rates_saved: bool,
}

#[cfg(test)]
mod tests;
