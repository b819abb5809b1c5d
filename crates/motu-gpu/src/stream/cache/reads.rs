//! A build group's cache decisions, made before its meshes load, and its directory reads run
//! beside the mesh uploads: on an H100 (island 0.63 at 24 GiB, warm) the reads were half of
//! the restores' 2.0 s and the group's mesh uploads took longer than its reads, on other cores
//! (BENCHMARKS.md, session 50). What the rule declines (`restore_rule.rs`) is never read.

use std::collections::HashSet;
use std::thread::JoinHandle;
use std::time::Instant;

use motu_ascache::{Blob, CacheKey, ReadPlan, ReadsDone, Tier};

use super::super::skeleton::ms_since;
use super::super::store_policy::HostStorePolicy;
use super::super::StreamingRenderer;

/// What [`StreamingRenderer::read_cached_ahead`] decided for a build group (consumed by its
/// restore, `restore_cached`).
#[derive(Default)]
pub(in crate::stream) struct GroupReads {
    /// BLASes whose entries are read from the directory, in the reads' order, with keys.
    disk: Vec<(usize, CacheKey)>,
    reading: Option<Reading>,
    /// BLASes the rule builds rather than restores (their entries are not read).
    declined: Vec<usize>,
}

/// The group's directory reads: on a thread of their own, or (no thread could be started)
/// still to run when they are needed.
enum Reading {
    Thread(JoinHandle<ReadsDone>),
    Later(ReadPlan),
}

impl GroupReads {
    /// The BLASes whose restore was decided here (read ahead or declined).
    pub(super) fn covered(&self) -> HashSet<usize> {
        self.disk
            .iter()
            .map(|d| d.0)
            .chain(self.declined.iter().copied())
            .collect()
    }

    pub(super) fn declined(&self) -> &[usize] {
        &self.declined
    }
}

/// What the restore rule says of one cached BLAS.
pub(super) enum Decision {
    /// Restore it from the tier that holds it (`Tier::Disk`: not in host memory).
    Restore(CacheKey, Tier),
    /// Not known to this process's index (another process may have written it since): looked
    /// up as before the rule.
    Unknown(CacheKey),
    /// Build it: the rule says its restore would not pay (counted), or it has no key.
    Build,
}

impl StreamingRenderer<'_> {
    /// The restore rule's decision for BLAS `b` (a decline counted in the frame).
    pub(super) fn decide_restore(&mut self, b: usize) -> Decision {
        let Some(key) = self.blas_key(b) else {
            return Decision::Build;
        };
        let a = self.reuse.cache.as_ref().expect("attached");
        let Some((tier, bytes)) = a.cache.cache.entry_bytes(&key) else {
            return Decision::Unknown(key);
        };
        // `--stream-host-cache-policy always`: every cached BLAS restored, as before the rule.
        let always = self.reuse.policy == HostStorePolicy::Always;
        if always
            || self
                .reuse
                .rule
                .restore_pays(&self.reuse.estimates, bytes, tier)
        {
            return Decision::Restore(key, tier);
        }
        let st = self.frame.stats_mut();
        match tier {
            Tier::Host => st.host_restore_declined += 1,
            Tier::Disk => {
                st.disk_restore_declined += 1;
                st.disk_restore_declined_bytes += bytes;
            }
        }
        Decision::Build
    }

    /// Decides which BLASes of build `group` are restored and starts reading those held only
    /// in the directory on a thread of its own, to run while the group's meshes load
    /// (`None`: no cache attached). BLASes held as host clones are left to their restore.
    pub(in crate::stream) fn read_cached_ahead(&mut self, group: &[u32]) -> Option<GroupReads> {
        self.reuse.cache.as_ref()?;
        let mut reads = GroupReads::default();
        let mut keys = Vec::new();
        for &b in group {
            let b = b as usize;
            if self.clones.holds(b) {
                continue;
            }
            match self.decide_restore(b) {
                Decision::Restore(key, Tier::Disk) => {
                    reads.disk.push((b, key));
                    keys.push(key);
                }
                Decision::Build => reads.declined.push(b),
                // Host hits cost no read; unknown keys are looked up at the restore.
                Decision::Restore(_, Tier::Host) | Decision::Unknown(_) => {}
            }
        }
        if keys.is_empty() {
            return Some(reads);
        }
        let a = self.reuse.cache.as_mut().expect("attached");
        let Some(plan) = a.cache.cache.plan_disk_reads(&keys) else {
            reads.disk.clear();
            return Some(reads);
        };
        let ctx = self.ctx.clone();
        let started = std::thread::Builder::new()
            .name("motu-cache-read".into())
            .spawn(move || {
                let compatible =
                    |h: &[u8; 32]| ctx.acceleration_structure_compatible(h).unwrap_or(false);
                plan.run(&compatible)
            });
        reads.reading = match started {
            Ok(handle) => Some(Reading::Thread(handle)),
            Err(e) => {
                tracing::debug!(error = %e, "no thread for the cache's reads; reading when needed");
                // The plan went into the closure that failed to start: plan again.
                let a = self.reuse.cache.as_mut().expect("attached");
                a.cache.cache.plan_disk_reads(&keys).map(Reading::Later)
            }
        };
        Some(reads)
    }

    /// The blobs `reads` read for BLASes `wanted` (others', restored another way meanwhile,
    /// dropped), with their keys; the frame's thread's wait is a sample of the restore rule's
    /// disk reads and part of `restore_read_ms`.
    pub(super) fn finish_group_reads(
        &mut self,
        reads: GroupReads,
        wanted: &HashSet<usize>,
    ) -> Vec<(usize, CacheKey, Option<Blob>)> {
        let Some(reading) = reads.reading else {
            return Vec::new();
        };
        let t = Instant::now();
        let done = match reading {
            Reading::Thread(handle) => handle.join().ok(),
            Reading::Later(plan) => {
                let ctx = self.ctx.clone();
                let compatible =
                    |h: &[u8; 32]| ctx.acceleration_structure_compatible(h).unwrap_or(false);
                Some(plan.run(&compatible))
            }
        };
        let Some(done) = done else {
            // A panicking reader is a bug; its BLASes are built.
            tracing::warn!("structure cache: the reading thread failed; building instead");
            return reads.disk.into_iter().map(|(b, k)| (b, k, None)).collect();
        };
        self.frame.stats_mut().restore_read_background_ms += done.read_ms;
        let a = self.reuse.cache.as_mut().expect("attached");
        let blobs = a.cache.cache.finish_disk_reads(done);
        let ms = ms_since(t);
        let (hits, bytes) = blobs
            .iter()
            .flatten()
            .fold((0u64, 0u64), |(n, s), b| (n + 1, s + b.len() as u64));
        self.reuse.rule.disk_read.add(hits, bytes, ms);
        self.frame.stats_mut().restore_read_ms += ms;
        reads
            .disk
            .into_iter()
            .zip(blobs)
            .filter(|((b, _), _)| wanted.contains(b))
            .map(|((b, k), blob)| (b, k, blob))
            .collect()
    }
}
