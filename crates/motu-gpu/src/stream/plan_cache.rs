//! The proxy clusters of a [`StreamPlan`] kept in the structure cache: a binned SAH over every
//! instance (about 2 s of island 0.63's start on the H200 host) becomes a read in the next
//! process. The key covers every table the clusters are made from (the TLASes, the instances
//! and the BLASes, hashed whole), so a plan read back is the plan [`StreamPlan::new`] would
//! make; a blob that does not decode to this view's shape is made again with a warning.

use std::sync::Arc;

use motu_abi::HierarchyView;
use motu_ascache::{CacheKey, CacheKeyBuilder, SERIALIZED_HEADER_BYTES};

use super::cache::StructureCache;
use super::topology::{ProxyCluster, StreamPlan};

/// Where a serialised structure has its driver's header: no driver accepts a plan as one.
const MAGIC: [u8; SERIALIZED_HEADER_BYTES] = *b"motu stream plan v1\0\0\0\0\0\0\0\0\0\0\0\0\0";
const DOMAIN: &str = "motu-stream-plan-v1";

impl StreamPlan {
    /// [`StreamPlan::new`], read from `cache` when an earlier process kept this view's plan
    /// there, else made and kept. Whether it was read is [`StreamPlan::from_cache`].
    pub fn new_cached(view: &HierarchyView<'_>, cache: &mut StructureCache) -> StreamPlan {
        let key = plan_key(view, cache.scene_identity());
        let shape = |h: &[u8; SERIALIZED_HEADER_BYTES]| *h == MAGIC;
        if let Some((blob, tier)) = cache.cache_mut().get(&key, &shape) {
            match decode(&blob, view) {
                Some(plan) => {
                    tracing::info!(?tier, "proxy clusters from the structure cache");
                    return plan;
                }
                None => {
                    tracing::warn!(
                        "structure cache: a stream plan that does not fit this view; made again"
                    );
                    cache.cache_mut().remove(&key);
                }
            }
        }
        let plan = StreamPlan::new(view);
        cache.cache_mut().put(key, encode(&plan));
        plan
    }
}

fn plan_key(view: &HierarchyView<'_>, scene_identity: &[u8]) -> CacheKey {
    let mut k = CacheKeyBuilder::new(DOMAIN);
    k.bytes(scene_identity)
        .u32(view.root_tlas)
        .bytes(bytemuck::cast_slice(view.tlases))
        .bytes(bytemuck::cast_slice(view.instances))
        .bytes(bytemuck::cast_slice(view.blases));
    k.finish()
}

/// The magic, the TLAS and instance counts (u64), then per TLAS its cluster count (u64) and
/// per cluster its BLAS, member start (u32 each), bounds (6 f32), member count (u64) and
/// members (u32).
fn encode(plan: &StreamPlan) -> Arc<[u8]> {
    let mut out = Vec::new();
    out.extend_from_slice(&MAGIC);
    out.extend_from_slice(&(plan.clusters.len() as u64).to_le_bytes());
    out.extend_from_slice(&(plan.instances as u64).to_le_bytes());
    for tlas in &plan.clusters {
        out.extend_from_slice(&(tlas.len() as u64).to_le_bytes());
        for c in tlas {
            out.extend_from_slice(&c.blas.to_le_bytes());
            out.extend_from_slice(&c.member_first.to_le_bytes());
            out.extend_from_slice(bytemuck::cast_slice(&c.bounds));
            out.extend_from_slice(&(c.members.len() as u64).to_le_bytes());
            out.extend_from_slice(bytemuck::cast_slice(&c.members));
        }
    }
    out.into()
}

/// Reads what [`encode`] wrote; `None` unless it is whole and shaped for `view` (its TLAS and
/// instance counts, member indices inside each TLAS's range, BLAS ids in range).
fn decode(blob: &[u8], view: &HierarchyView<'_>) -> Option<StreamPlan> {
    let mut r = Reader(blob.strip_prefix(&MAGIC[..])?);
    let tlases = r.u64()? as usize;
    let instances = r.u64()? as usize;
    if tlases != view.tlases.len() || instances != view.instances.len() {
        return None;
    }
    let mut clusters = Vec::with_capacity(tlases);
    for t in view.tlases {
        let n = r.u64()? as usize;
        let mut list = Vec::with_capacity(n.min(1 << 20));
        for _ in 0..n {
            let blas = r.u32()?;
            let member_first = r.u32()?;
            let mut bounds = [0f32; 6];
            for b in &mut bounds {
                *b = f32::from_le_bytes(r.take(4)?.try_into().ok()?);
            }
            let count = r.u64()? as usize;
            let bytes = r.take(count.checked_mul(4)?)?;
            let members: Vec<u32> = bytes
                .chunks_exact(4)
                .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect();
            if blas as usize >= view.blases.len() || members.iter().any(|&m| m >= t.instance_count)
            {
                return None;
            }
            list.push(ProxyCluster {
                blas,
                bounds,
                members,
                member_first,
            });
        }
        clusters.push(list);
    }
    r.0.is_empty().then_some(StreamPlan {
        clusters,
        instances,
        from_cache: true,
    })
}

struct Reader<'a>(&'a [u8]);

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        if self.0.len() < n {
            return None;
        }
        let (head, tail) = self.0.split_at(n);
        self.0 = tail;
        Some(head)
    }
    fn u32(&mut self) -> Option<u32> {
        Some(u32::from_le_bytes(self.take(4)?.try_into().ok()?))
    }
    fn u64(&mut self) -> Option<u64> {
        Some(u64::from_le_bytes(self.take(8)?.try_into().ok()?))
    }
}

#[cfg(test)]
mod tests;
