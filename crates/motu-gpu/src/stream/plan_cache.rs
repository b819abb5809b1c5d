//! Where a [`StreamPlan`]'s proxy clusters come from, in order: the package's
//! `proxy_clusters` section (made by `motu import` over the stream split:
//! `motu_compile::proxy_clusters`), the structure cache, or made here. A binned SAH over every
//! instance (about 2 s of island 0.63's start on the H200 host) becomes a read.
//!
//! The package's table is used TLAS by TLAS where its entry's hash matches the view (a table of
//! another shape, from another split or an element subset, is not used at all); a stale entry is
//! a warning and its TLAS is made again. The structure cache's key covers every table the
//! clusters are made from (the TLASes, the instances and the BLASes, hashed whole), so a plan read
//! back is the plan [`StreamPlan::new`] would make; a blob that does not decode to this view's
//! shape is made again with a warning.

use motu_abi::blob::{BlobReader, BlobWriter};
use motu_abi::HierarchyView;
use motu_ascache::{Blob, CacheKey, CacheKeyBuilder, SERIALIZED_HEADER_BYTES};
use motu_compile::proxy_clusters::{blases_hash, decode_section, Stored};
use rayon::prelude::*;

use super::cache::StructureCache;
use super::topology::{proxy_clusters, ClustersSource, ProxyCluster, StreamPlan};

/// Where a serialised structure has its driver's header: no driver accepts a plan as one.
const MAGIC: [u8; SERIALIZED_HEADER_BYTES] = *b"motu stream plan v1\0\0\0\0\0\0\0\0\0\0\0\0\0";
const DOMAIN: &str = "motu-stream-plan-v1";

impl StreamPlan {
    /// [`StreamPlan::new`], read from `cache` when an earlier process kept this view's plan
    /// there, else made and kept. Whether it was read is [`StreamPlan::from_cache`].
    pub fn new_cached(view: &HierarchyView<'_>, cache: &mut StructureCache) -> StreamPlan {
        StreamPlan::load(view, None, Some(cache))
    }

    /// [`StreamPlan::new`] from, in order: `stored` (a package's `proxy_clusters` section)
    /// where every TLAS's entry matches `view`; `cache`; else made (the TLASes the stored table
    /// had valid entries for taken from it) and kept in `cache`. Where they came from is
    /// [`StreamPlan::source`]; a table that cannot be read or whose entries do not match is a
    /// warning, never used.
    pub fn load(
        view: &HierarchyView<'_>,
        stored: Option<&[u8]>,
        mut cache: Option<&mut StructureCache>,
    ) -> StreamPlan {
        let _span = tracing::info_span!("proxy_clusters", tlases = view.tlases.len()).entered();
        let mut partial = None;
        let mut stale_tlases = 0;
        if let Some(bytes) = stored {
            match from_stored(view, bytes) {
                Err(Unused::Unknown) => tracing::warn!(
                    bytes = bytes.len(),
                    "the package's proxy-cluster table is not one this reader knows (another \
                     version, or damaged); the clusters are made again"
                ),
                // Another split (`--stream-split-instances`) or an element subset: expected.
                Err(Unused::OtherShape) => tracing::info!(
                    "the package's proxy-cluster table is for another hierarchy (stream split \
                     or subset); the clusters are made"
                ),
                Ok(found) => {
                    let stale = found.iter().filter(|c| c.is_none()).count();
                    if stale == 0 {
                        tracing::info!(tlases = found.len(), "proxy clusters from the package");
                        return StreamPlan {
                            clusters: found.into_iter().flatten().collect(),
                            instances: view.instances.len(),
                            source: ClustersSource::Package,
                            stale_tlases: 0,
                        };
                    }
                    tracing::warn!(
                        stale,
                        tlases = found.len(),
                        "the package's proxy-cluster table does not match {stale} TLASes \
                         (changed since import); their clusters are made again"
                    );
                    stale_tlases = stale as u64;
                    partial = Some(found);
                }
            }
        }
        let key = cache.as_ref().map(|c| plan_key(view, c.scene_identity()));
        if let (Some(c), Some(key)) = (cache.as_deref_mut(), key.as_ref()) {
            if let Some(mut plan) = cached(view, c, key) {
                plan.stale_tlases = stale_tlases;
                return plan;
            }
        }
        let clusters = match partial {
            None => (0..view.tlases.len())
                .into_par_iter()
                .map(|t| proxy_clusters(view, t))
                .collect(),
            Some(found) => found
                .into_par_iter()
                .enumerate()
                .map(|(t, c)| c.unwrap_or_else(|| proxy_clusters(view, t)))
                .collect(),
        };
        let plan = StreamPlan {
            clusters,
            instances: view.instances.len(),
            source: ClustersSource::Computed,
            stale_tlases,
        };
        if let (Some(c), Some(key)) = (cache, key) {
            c.cache_mut().put(key, encode(&plan));
        }
        plan
    }
}

/// Why a package's table is not used at all.
enum Unused {
    /// Another version of the section, or damaged.
    Unknown,
    /// Made for a view of another shape (TLAS or instance count).
    OtherShape,
}

/// Per TLAS of `view`, its clusters from a package's section (`None`: its entry is stale), or
/// why the section is not used at all.
#[allow(clippy::type_complexity)]
fn from_stored(
    view: &HierarchyView<'_>,
    bytes: &[u8],
) -> Result<Vec<Option<Vec<ProxyCluster>>>, Unused> {
    let stored = decode_section(bytes).ok_or(Unused::Unknown)?;
    if !stored.fits(view) {
        return Err(Unused::OtherShape);
    }
    let bh = blases_hash(view);
    Ok((0..view.tlases.len())
        .into_par_iter()
        .map(|t| match stored.tlas_clusters(view, t, bh) {
            Stored::Valid(c) => Some(c.into_iter().map(ProxyCluster::from).collect()),
            Stored::Stale => None,
        })
        .collect())
}

/// The plan `cache` kept under `key`, if it decodes to `view`'s shape (else removed).
fn cached(
    view: &HierarchyView<'_>,
    cache: &mut StructureCache,
    key: &CacheKey,
) -> Option<StreamPlan> {
    let shape = |h: &[u8; SERIALIZED_HEADER_BYTES]| *h == MAGIC;
    let (blob, tier) = cache.cache_mut().get(key, &shape)?;
    match decode(&blob, view) {
        Some(plan) => {
            tracing::info!(?tier, "proxy clusters from the structure cache");
            Some(plan)
        }
        None => {
            tracing::warn!(
                "structure cache: a stream plan that does not fit this view; made again"
            );
            cache.cache_mut().remove(key);
            None
        }
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
fn encode(plan: &StreamPlan) -> Blob {
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
        source: ClustersSource::Cache,
        stale_tlases: 0,
    })
}

#[cfg(test)]
mod tests;
