//! The topology part ([`Topology`]): what the view implies for streaming and never changes
//! after the start: which BLASes stream, each BLAS's parent TLASes with its instance counts in
//! them, each TLAS's proxy clusters ([`StreamPlan`]) and the GPU slots of its proxy and marks
//! BLASes; and the GPU tables' records derived from them ([`SkeletonRecords`], uploaded by
//! `skeleton.rs`).
//!
//! Invariants: every vector is indexed by the view's BLAS or TLAS ids and sized to them;
//! nothing here is written after [`Topology::derive`] (the cluster member ranges are set
//! there), so the GPU slots it names stay valid for the renderer's life.

use motu_abi::{BlasRecord, HierarchyView, PiRecord, TlasRecord, BLAS_AABBS, NONE_U32};

use motu_compile::proxy_clusters::{tlas_clusters, Cluster};

use rayon::prelude::*;

use super::instance_table::InstanceTable;
use super::member_boxes::{member_box, Quantiser, MEMBER_WORDS};
use super::PI_EMPTY_BLAS;
use crate::error::{GpuError, Result};

/// One proxy box: a spatially coherent cluster of a TLAS's instances of one triangle BLAS
/// (`motu_compile::proxy_clusters`), with where its members start in the GPU member table.
#[derive(Clone, Debug)]
pub(super) struct ProxyCluster {
    pub blas: u32,
    /// `[min, max]` in the TLAS's space: the union of the instances' transformed BLAS bounds.
    pub bounds: [f32; 6],
    /// The member instances: indices in the TLAS's instance range (= their custom index).
    pub members: Vec<u32>,
    /// The cluster's first word in the GPU member table (its members' quantised boxes, then
    /// their global instance-table indices, `member_boxes.rs`): a ray that enters the box
    /// tests the members' boxes, so a BLAS is demanded only by rays that enter one of its
    /// instances' boxes (set by [`Topology::derive`]).
    pub member_first: u32,
}

impl From<Cluster> for ProxyCluster {
    fn from(c: Cluster) -> ProxyCluster {
        ProxyCluster {
            blas: c.blas,
            bounds: c.bounds,
            members: c.members,
            member_first: 0,
        }
    }
}

/// The proxy clusters of TLAS `t` (`motu_compile::proxy_clusters::tlas_clusters`: its
/// instances of each streamable BLAS, cut by the compiler's binned SAH into pieces of at most
/// `CLUSTER_INSTANCES`, in BLAS order). Deterministic: the importer (which stores them), the
/// renderer and the floor ([`super::streaming_floor`]) get the same clusters.
pub(super) fn proxy_clusters(view: &HierarchyView<'_>, t: usize) -> Vec<ProxyCluster> {
    tlas_clusters(view, t)
        .into_iter()
        .map(ProxyCluster::from)
        .collect()
}

/// Where a [`StreamPlan`]'s clusters came from (`stream.startup.clusters_source` in `--stats`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ClustersSource {
    /// The package's `proxy_clusters` section, stored at import.
    Package,
    /// The structure cache, kept by an earlier process.
    Cache,
    /// Made here (binned SAH over every instance), in part or whole.
    Computed,
}

impl ClustersSource {
    pub fn as_str(self) -> &'static str {
        match self {
            ClustersSource::Package => "package",
            ClustersSource::Cache => "cache",
            ClustersSource::Computed => "computed",
        }
    }
}

/// What the floor ([`super::streaming_floor_planned`]) and the renderer
/// ([`StreamingRenderer::with_plan`](super::StreamingRenderer::with_plan)) both derive from a view before anything is built: the
/// proxy clusters of every TLAS (binned SAH over millions of instances: seconds at island
/// scale, so made once per render, the TLASes in parallel, or read from the package or the
/// structure cache: `plan_cache.rs`).
pub struct StreamPlan {
    pub(super) clusters: Vec<Vec<ProxyCluster>>,
    pub(super) instances: usize,
    pub(super) source: ClustersSource,
    /// TLASes whose entry in the package's table was made for another view (made here).
    pub(super) stale_tlases: u64,
}

impl StreamPlan {
    pub fn new(view: &HierarchyView<'_>) -> StreamPlan {
        use rayon::prelude::*;
        let _span = tracing::info_span!("proxy_clusters", tlases = view.tlases.len()).entered();
        let clusters = (0..view.tlases.len())
            .into_par_iter()
            .map(|t| proxy_clusters(view, t))
            .collect();
        StreamPlan {
            clusters,
            instances: view.instances.len(),
            source: ClustersSource::Computed,
            stale_tlases: 0,
        }
    }

    /// Whether the clusters were read from the structure cache instead of made.
    pub fn from_cache(&self) -> bool {
        self.source == ClustersSource::Cache
    }

    /// Where the clusters came from.
    pub fn source(&self) -> ClustersSource {
        self.source
    }

    /// TLASes whose stored clusters did not match the view (made again).
    pub fn stale_tlases(&self) -> u64 {
        self.stale_tlases
    }

    /// A plan made for another view is a caller's mistake, refused rather than trusted.
    pub(super) fn check(&self, view: &HierarchyView<'_>) -> Result<()> {
        if self.clusters.len() != view.tlases.len() || self.instances != view.instances.len() {
            return Err(GpuError::InvalidRequest(format!(
                "streaming: a plan of {} TLASes and {} instances for a view of {} and {}",
                self.clusters.len(),
                self.instances,
                view.tlases.len(),
                view.instances.len()
            )));
        }
        Ok(())
    }
}

/// The topology of a [`StreamingRenderer`](super::StreamingRenderer) (see the module docs).
pub(super) struct Topology {
    /// Per BLAS: streamed (built on demand, evicted; [`super::streamable`]).
    buildable: Vec<bool>,
    /// Per BLAS: TLASes instancing it.
    parents: Vec<Vec<u32>>,
    /// Per BLAS: its instance count in each of `parents` (same order).
    parent_counts: Vec<Vec<u32>>,
    /// Per TLAS: its proxy boxes (clusters of triangle instances of one BLAS).
    clusters: Vec<Vec<ProxyCluster>>,
    /// Per TLAS: first proxy PI slot in the GPU tables (`NONE_U32`: no clusters).
    proxy_pi_base: Vec<u32>,
    /// Per TLAS: the GPU BLAS record of its marks BLAS (`NONE_U32`: no clusters), rewritten
    /// with each rebuild.
    marks_blas: Vec<u32>,
}

/// The GPU copies of the node tables (TLAS ranges grown by the proxy and marks instances,
/// proxy and marks BLAS records and PI slots after the originals) and the proxy clusters'
/// member table: what the skeleton uploads.
pub(super) struct SkeletonRecords {
    pub tlases: Vec<TlasRecord>,
    /// Each TLAS's instances, then its proxy and marks instances (written into the upload
    /// ring from the view, never copied whole).
    pub instances: InstanceTable,
    pub blases: Vec<BlasRecord>,
    pub pis: Vec<PiRecord>,
    /// Per cluster, its members' quantised boxes and global indices in the GPU instance table
    /// (`member_boxes.rs`).
    pub members: Vec<u32>,
}

fn too_many(what: &str) -> GpuError {
    GpuError::InvalidRequest(format!("streaming: too many {what}"))
}

impl Topology {
    /// The topology of `view` with `plan`'s clusters (checked against it by the caller), and
    /// the GPU tables' records.
    pub fn derive(
        view: &HierarchyView<'_>,
        plan: StreamPlan,
    ) -> Result<(Topology, SkeletonRecords)> {
        let nb = view.blases.len();
        let buildable: Vec<bool> = view.blases.iter().map(super::streamable).collect();
        let mut parents: Vec<Vec<u32>> = vec![Vec::new(); nb];
        let mut parent_counts: Vec<Vec<u32>> = vec![Vec::new(); nb];
        // TLASes are visited once each, in order, so a BLAS's current parent is the last in
        // its list: O(1) an instance (a search of the list cost ~1 s at 26M instances over
        // the split root's 35 pieces).
        let mut last_parent = vec![NONE_U32; nb];
        for (t, rec) in view.tlases.iter().enumerate() {
            let t = t as u32;
            for inst in &view.instances[rec.instance_range()] {
                let b = inst.blas as usize;
                if last_parent[b] != t {
                    last_parent[b] = t;
                    parents[b].push(t);
                    parent_counts[b].push(0);
                }
                if let Some(n) = parent_counts[b].last_mut() {
                    *n += 1;
                }
            }
        }
        let mut clusters = plan.clusters;
        let members = member_table(view, &mut clusters)?;
        let mut topo = Topology {
            buildable,
            parents,
            parent_counts,
            clusters,
            proxy_pi_base: Vec::new(),
            marks_blas: Vec::new(),
        };
        let records = topo.gpu_records(view, members)?;
        Ok((topo, records))
    }

    /// The GPU tables: TLAS ranges grow by the proxy and marks instances; proxy and marks
    /// BLAS records and PI slots (one per cluster, shared: non-resident clusters first, then
    /// resident ones, rewritten with each rebuild) follow the originals. Sets the proxies'
    /// PI bases and the marks' BLAS records.
    fn gpu_records(
        &mut self,
        view: &HierarchyView<'_>,
        members: Vec<u32>,
    ) -> Result<SkeletonRecords> {
        let nt = view.tlases.len();
        let mut out = SkeletonRecords {
            tlases: Vec::with_capacity(nt),
            instances: InstanceTable::default(),
            blases: view.blases.to_vec(),
            pis: view.pis.to_vec(),
            members,
        };
        self.proxy_pi_base = vec![NONE_U32; nt];
        self.marks_blas = vec![NONE_U32; nt];
        for (t, rec) in view.tlases.iter().enumerate() {
            let range = rec.instance_range();
            let mut count = rec.instance_count;
            let clusters = &self.clusters[t];
            let mut proxy_blas = None;
            if !clusters.is_empty() {
                let pi_base = u32::try_from(out.pis.len()).map_err(|_| too_many("PIs"))?;
                let blas_id = u32::try_from(out.blases.len()).map_err(|_| too_many("BLASes"))?;
                // The proxy and marks instances carry their BLAS record in the 24-bit custom
                // index (`tlas_encode.rs`).
                if blas_id + 1 >= 1 << 24 {
                    return Err(GpuError::InvalidRequest(format!(
                        "streaming: BLAS record {} of a proxy is over the instance custom \
                         index's limit 2^24 - 1",
                        blas_id + 1
                    )));
                }
                self.proxy_pi_base[t] = pi_base;
                for c in clusters {
                    out.pis.push(proxy_pi(c));
                }
                let n = clusters.len() as u32;
                // The proxy (non-resident clusters), then the marks (resident ones: none yet).
                out.blases.push(proxy_blas_record(rec, pi_base, n));
                out.blases.push(proxy_blas_record(rec, pi_base + n, 0));
                self.marks_blas[t] = blas_id + 1;
                proxy_blas = Some(blas_id);
                count += 2;
            }
            let base = out.instances.push(range.start, range.len(), proxy_blas);
            let base = u32::try_from(base).map_err(|_| too_many("instances"))?;
            out.tlases.push(TlasRecord {
                instance_base: base,
                instance_count: count,
                // No box lists: streamed TLASes keep every PI (and proxy) in the hardware walk.
                box_list_instances: 0,
                ..*rec
            });
        }
        Ok(out)
    }

    /// Whether BLAS `b` streams.
    pub fn buildable(&self, b: usize) -> bool {
        self.buildable[b]
    }

    /// Per BLAS: whether it streams.
    pub fn buildable_all(&self) -> &[bool] {
        &self.buildable
    }

    /// The TLASes instancing BLAS `b`.
    pub fn parents(&self, b: usize) -> &[u32] {
        &self.parents[b]
    }

    /// TLAS `t`'s proxy clusters, in box order of the GPU tables.
    pub fn clusters(&self, t: usize) -> &[ProxyCluster] {
        &self.clusters[t]
    }

    /// Per TLAS: whether it has proxy clusters.
    pub fn has_clusters(&self) -> Vec<bool> {
        self.clusters.iter().map(|c| !c.is_empty()).collect()
    }

    /// TLAS `t`'s first proxy PI slot and the GPU BLAS record of its marks BLAS (both
    /// `NONE_U32` without clusters).
    pub fn proxy_slots(&self, t: usize) -> (u32, u32) {
        (self.proxy_pi_base[t], self.marks_blas[t])
    }

    /// The GPU BLAS record of TLAS `t`'s proxy (`marks` false) or marks BLAS (the custom
    /// index of its instance, `tlas_encode.rs`); `NONE_U32` without clusters.
    pub fn proxy_blas_record(&self, t: usize, marks: bool) -> u32 {
        match self.marks_blas[t] {
            NONE_U32 => NONE_U32,
            marks_blas => marks_blas - u32::from(!marks),
        }
    }

    /// Streamed BLASes: how many there are.
    pub fn buildable_count(&self) -> usize {
        self.buildable.iter().filter(|&&b| b).count()
    }

    /// Adds BLAS `b`'s instance records to `counts`, per parent TLAS.
    pub fn add_instance_counts(&self, b: u32, counts: &mut [u64]) {
        let b = b as usize;
        for (&t, &n) in self.parents[b].iter().zip(&self.parent_counts[b]) {
            counts[t as usize] += u64::from(n);
        }
    }
}

/// The member table: per cluster, its members' quantised boxes, then their global indices in
/// the GPU instance table (`member_boxes.rs` has the layout; each TLAS's range in the instance
/// table starts at the running total of the ranges before it, each grown by its proxy and
/// marks instances). Sets each cluster's `member_first` (its first word). The boxes of each
/// TLAS are made on the pool: 17M members on one thread would cost about a second.
fn member_table(view: &HierarchyView<'_>, clusters: &mut [Vec<ProxyCluster>]) -> Result<Vec<u32>> {
    let mut first_word = 0usize;
    let mut gpu_base = 0u32;
    let mut tlas_firsts = Vec::with_capacity(view.tlases.len());
    for (t, rec) in view.tlases.iter().enumerate() {
        tlas_firsts.push((first_word, gpu_base));
        for c in &mut clusters[t] {
            c.member_first = u32::try_from(first_word).map_err(|_| too_many("instances"))?;
            first_word += MEMBER_WORDS * c.members.len();
        }
        let grown = rec.instance_count + 2 * u32::from(!clusters[t].is_empty());
        gpu_base = gpu_base
            .checked_add(grown)
            .ok_or_else(|| too_many("instances"))?;
    }
    u32::try_from(first_word).map_err(|_| too_many("instances"))?;
    let mut words = vec![0u32; first_word];
    // Each TLAS's words, split off in order (each TLAS's first word from the loop above).
    let mut parts = Vec::with_capacity(view.tlases.len());
    let mut rest = words.as_mut_slice();
    for t in 0..view.tlases.len() {
        let end = tlas_firsts.get(t + 1).map_or(first_word, |&(w, _)| w);
        let (part, tail) = rest.split_at_mut(end - tlas_firsts[t].0);
        parts.push((t, part));
        rest = tail;
    }
    parts
        .into_par_iter()
        .for_each(|(t, part)| tlas_member_words(view, t, &clusters[t], tlas_firsts[t], part));
    Ok(words)
}

/// TLAS `t`'s words of the member table (`part`, from word `first` of the table; its instances
/// from `gpu_base` in the GPU instance table). The instances are read in their own order: read
/// cluster by cluster, each member's record was a cache and TLB miss in the mapped package
/// (~250 ns a member on the 2-core box, 0.35 s of island 0.05's start). Their boxes are
/// quantised on the pool in instance order (one TLAS may hold most instances: the root's
/// pieces are few), then placed cluster by cluster (8 bytes an instance, this TLAS only).
fn tlas_member_words(
    view: &HierarchyView<'_>,
    t: usize,
    clusters: &[ProxyCluster],
    (first, gpu_base): (usize, u32),
    part: &mut [u32],
) {
    let instances = &view.instances[view.tlases[t].instance_range()];
    // Per instance: its cluster (NONE_U32: none).
    let mut cluster_of = vec![NONE_U32; instances.len()];
    for (ci, c) in clusters.iter().enumerate() {
        for &local in &c.members {
            cluster_of[local as usize] = ci as u32;
        }
    }
    let quantisers: Vec<Quantiser> = clusters.iter().map(|c| Quantiser::new(&c.bounds)).collect();
    let boxes: Vec<[u32; 2]> = instances
        .par_iter()
        .zip(cluster_of.par_iter())
        .with_min_len(4096)
        .map(|(inst, &ci)| {
            if ci == NONE_U32 {
                return [0; 2];
            }
            let blas = &view.blases[clusters[ci as usize].blas as usize];
            let b = member_box(&inst.tlas_from_blas, blas.bounds_min, blas.bounds_max);
            quantisers[ci as usize].quantise(&b)
        })
        .collect();
    drop(cluster_of);
    for c in clusters {
        let at = c.member_first as usize - first;
        let n = c.members.len();
        for (i, &local) in c.members.iter().enumerate() {
            let q = boxes[local as usize];
            part[at + 2 * i] = q[0];
            part[at + 2 * i + 1] = q[1];
            part[at + 2 * n + i] = gpu_base + local;
        }
    }
}

/// The GPU BLAS record of TLAS `rec`'s proxy or marks BLAS: `n` PI slots from `item_base`.
pub(super) fn proxy_blas_record(rec: &TlasRecord, item_base: u32, n: u32) -> BlasRecord {
    BlasRecord {
        kind: BLAS_AABBS,
        item_base,
        item_count: n,
        level: rec.level + 1,
        bounds_min: rec.bounds_min,
        primitive_count: n,
        bounds_max: rec.bounds_max,
        _pad: 0,
    }
}

/// The PI record of cluster `c`'s proxy box. A proxy has no child transform: its first two
/// words (`child_from_parent[0..2]`, read as u32 by `candidates.glsl`'s `record_proxy`)
/// carry the cluster's first word in the member table and its member count.
pub(super) fn proxy_pi(c: &ProxyCluster) -> PiRecord {
    let b = &c.bounds;
    let mut child_from_parent = [0.0f32; 12];
    child_from_parent[0] = f32::from_bits(c.member_first);
    child_from_parent[1] = f32::from_bits(c.members.len() as u32);
    PiRecord {
        child_from_parent,
        aabb_min: [b[0], b[1], b[2]],
        kind: PI_EMPTY_BLAS,
        aabb_max: [b[3], b[4], b[5]],
        target: c.blas,
    }
}

#[cfg(test)]
mod tests;
