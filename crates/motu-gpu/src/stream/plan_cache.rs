//! The proxy clusters of a [`StreamPlan`] kept in the structure cache: a binned SAH over every
//! instance (about 2 s of island 0.63's start on the H200 host) becomes a read in the next
//! process. The key covers every table the clusters are made from (the TLASes, the instances
//! and the BLASes, hashed whole), so a plan read back is the plan [`StreamPlan::new`] would
//! make; a blob that does not decode to this view's shape is made again with a warning.

use std::sync::Arc;

use motu_abi::blob::{BlobReader, BlobWriter};
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
    let mut w = BlobWriter::new(&MAGIC, 0);
    w.u64(plan.clusters.len() as u64).u64(plan.instances as u64);
    for tlas in &plan.clusters {
        w.u64(tlas.len() as u64);
        for c in tlas {
            w.u32(c.blas)
                .u32(c.member_first)
                .pods(&c.bounds)
                .u64(c.members.len() as u64)
                .pods(&c.members);
        }
    }
    w.finish().into()
}

/// Reads what [`encode`] wrote; `None` unless it is whole and shaped for `view` (its TLAS and
/// instance counts, member indices inside each TLAS's range, BLAS ids in range).
fn decode(blob: &[u8], view: &HierarchyView<'_>) -> Option<StreamPlan> {
    let mut r = BlobReader::new(blob, &MAGIC)?;
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
            let bounds: [f32; 6] = r.pods::<f32>(6)?.try_into().ok()?;
            let count = usize::try_from(r.u64()?).ok()?;
            let members: Vec<u32> = r.pods(count)?;
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
    r.finish()?;
    Some(StreamPlan {
        clusters,
        instances,
        from_cache: true,
    })
}

#[cfg(test)]
mod tests;
