//! Proxy clusters of a TLAS: the maths, and the table a package stores.
//!
//! A streamed render (`motu-gpu` `stream/topology.rs`) stands each spatially coherent cluster
//! of a TLAS's instances of one triangle BLAS by one proxy box, cut by the binned SAH
//! ([`crate::sah_partition`]) over the instances' transformed BLAS bounds into pieces of at most
//! [`CLUSTER_INSTANCES`]. Over millions of instances that is seconds (about 2 s of island
//! 0.63's start on the H200 host, and most of `motu report`'s time), so `motu import` makes
//! the clusters once, over the hierarchy the streamer renders (the package's stream split), and
//! stores them in the package's `proxy_clusters` section ([`encode_section`], FORMAT.md).
//!
//! A reader uses a TLAS's stored clusters only when the entry's hash ([`tlas_hash`]: the TLAS's
//! record, its instances and the whole BLAS table) matches the view it renders, and makes the
//! others itself ([`tlas_clusters`]), so a stale or foreign table never changes an image.
//! Deterministic: the same view gives the same clusters, stored or made.

use motu_abi::blob::{BlobReader, BlobWriter};
use motu_abi::HierarchyView;

use crate::proxy_boxes::{has_boxes, padded, Box6, EMPTY};

/// Triangle instances of one BLAS per proxy box at most. One box per instance made the
/// resident skeleton (proxy BLAS, PI records, and the TLAS sized for every instance) grow with
/// the instance count: 26 MB of the default island's 46 MB floor. A box over a cluster of
/// neighbouring instances of the same BLAS stays exact where it matters (the BLAS is open for a
/// ray that enters the box, a superset of the rays that could hit an instance) and only costs
/// a build when a ray passes between the instances before the BLAS was walked.
pub const CLUSTER_INSTANCES: usize = 16;

/// Instances a batch of [`StoredProxyClusters::of_view`] holds at most a thread (but for a
/// batch of one TLAS, and at least 1M a batch): its temporaries, ~30 bytes an instance, stay
/// ~16 MB a thread. A bound of 1M whatever the threads made island 0.63's clusters one
/// 1M-instance root piece at a time: 1.4 → 11.4 s on a 16-core host (session 40).
const BATCH_INSTANCES_PER_THREAD: usize = 1 << 19;

/// One proxy box: a spatially coherent cluster of a TLAS's instances of one triangle BLAS.
#[derive(Clone, Debug, PartialEq)]
pub struct Cluster {
    pub blas: u32,
    /// `[min, max]` in the TLAS's space: the union of the instances' transformed BLAS bounds,
    /// padded ([`padded`]).
    pub bounds: Box6,
    /// The member instances: indices in the TLAS's instance range.
    pub members: Vec<u32>,
}

/// `[min, max]` of the box `lo..hi` under the affine map `m`.
pub fn transformed_box(m: &[f32; 12], lo: [f32; 3], hi: [f32; 3]) -> Box6 {
    let mut out = EMPTY;
    for c in 0..8 {
        let p = [
            if c & 1 == 0 { lo[0] } else { hi[0] },
            if c & 2 == 0 { lo[1] } else { hi[1] },
            if c & 4 == 0 { lo[2] } else { hi[2] },
        ];
        let q = motu_abi::xform_point(m, p);
        for a in 0..3 {
            out[a] = out[a].min(q[a]);
            out[3 + a] = out[3 + a].max(q[a]);
        }
    }
    out
}

/// The proxy clusters of TLAS `t`: its instances of each BLAS with boxes ([`has_boxes`]: what
/// a streamer streams), cut by the binned SAH over instance bounds into pieces of at most
/// [`CLUSTER_INSTANCES`], in BLAS order ([`tlas_cluster_table`] as a list).
pub fn tlas_clusters(view: &HierarchyView<'_>, t: usize) -> Vec<Cluster> {
    let (clusters, members) = tlas_cluster_table(view, t);
    let mut first = 0;
    clusters
        .iter()
        .map(|c| {
            let end = first + c.member_count as usize;
            let members = members[first..end].to_vec();
            first = end;
            Cluster {
                blas: c.blas,
                bounds: c.bounds,
                members,
            }
        })
        .collect()
}

/// A TLAS's clusters in the stored table's form ([`tlas_cluster_table`]): the clusters, and
/// their members one cluster after another.
pub type ClusterTable = (Vec<StoredCluster>, Vec<u32>);

/// [`tlas_clusters`] in the stored table's form: the clusters, and their members one cluster
/// after another. The instances of each BLAS take one span of a single items array (counted
/// first, so nothing grows by doubling) that the SAH permutes in place; its ranges tile the
/// span in order, so the permuted items are the member table. About 30 bytes an instance of
/// the TLAS while it is made (an index, its bounds, a cluster per 16).
pub fn tlas_cluster_table(view: &HierarchyView<'_>, t: usize) -> ClusterTable {
    let rec = &view.tlases[t];
    let instances = &view.instances[rec.instance_range()];
    // Per BLAS with boxes, its instances' count, then the start of its span (BLAS order).
    let mut next: std::collections::BTreeMap<u32, usize> = Default::default();
    for inst in instances {
        if has_boxes(&view.blases[inst.blas as usize]) {
            *next.entry(inst.blas).or_default() += 1;
        }
    }
    let mut spans = Vec::with_capacity(next.len());
    let mut total = 0;
    for (&blas, slot) in next.iter_mut() {
        let count = *slot;
        spans.push((blas, total, total + count));
        *slot = total;
        total += count;
    }
    let mut items = vec![0u32; total];
    let mut bounds: Vec<([f32; 3], [f32; 3])> = vec![([0.0; 3], [0.0; 3]); total];
    for (local, inst) in instances.iter().enumerate() {
        let br = &view.blases[inst.blas as usize];
        if !has_boxes(br) {
            continue;
        }
        let slot = next.get_mut(&inst.blas).expect("counted");
        let x = transformed_box(&inst.tlas_from_blas, br.bounds_min, br.bounds_max);
        items[*slot] = local as u32;
        bounds[*slot] = ([x[0], x[1], x[2]], [x[3], x[4], x[5]]);
        *slot += 1;
    }
    let mut clusters = Vec::new();
    let mut ranges = Vec::new();
    for (blas, begin, end) in spans {
        ranges.clear();
        crate::sah_partition(
            &mut items[begin..end],
            &mut bounds[begin..end],
            CLUSTER_INSTANCES,
            &mut ranges,
        );
        for &(b, e) in &ranges {
            let mut bx = EMPTY;
            for (lo, hi) in &bounds[begin + b..begin + e] {
                for a in 0..3 {
                    bx[a] = bx[a].min(lo[a]);
                    bx[3 + a] = bx[3 + a].max(hi[a]);
                }
            }
            clusters.push(StoredCluster {
                blas,
                member_count: (e - b) as u32,
                bounds: padded(bx),
            });
        }
    }
    (clusters, items)
}

/// [`tlas_clusters`] of every TLAS, the TLASes in parallel.
pub fn all_clusters(view: &HierarchyView<'_>) -> Vec<Vec<Cluster>> {
    use rayon::prelude::*;
    (0..view.tlases.len())
        .into_par_iter()
        .map(|t| tlas_clusters(view, t))
        .collect()
}

const HASH_DOMAIN: &[u8] = b"motu-proxy-clusters-tlas-v1";

/// The whole BLAS table hashed (each TLAS's hash covers it: a cluster reads its BLAS's kind,
/// item count and bounds).
pub fn blases_hash(view: &HierarchyView<'_>) -> u64 {
    xxhash_rust::xxh3::xxh3_64(bytemuck::cast_slice(view.blases))
}

/// What TLAS `t`'s clusters are made from, hashed: the maths' constant, the BLAS table
/// ([`blases_hash`]), the TLAS's record and its instance records. A stored entry whose hash
/// differs was made for another view and is not used.
pub fn tlas_hash(view: &HierarchyView<'_>, t: usize, blases_hash: u64) -> u64 {
    let mut h = xxhash_rust::xxh3::Xxh3::new();
    h.update(HASH_DOMAIN);
    h.update(&(CLUSTER_INSTANCES as u32).to_le_bytes());
    h.update(&blases_hash.to_le_bytes());
    let rec = &view.tlases[t];
    h.update(bytemuck::bytes_of(rec));
    let range = rec.instance_range();
    h.update(bytemuck::cast_slice(
        view.instances.get(range).unwrap_or(&[]),
    ));
    h.digest()
}

/// The `proxy_clusters` section's first bytes (FORMAT.md): the name and the version.
pub const SECTION_MAGIC: &[u8; 16] = b"motu pclust v1\0\0";

/// One TLAS's entry of a stored table: [`tlas_hash`], its first cluster and cluster count.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct StoredTlas {
    pub hash: u64,
    pub first_cluster: u64,
    pub cluster_count: u64,
}

/// One stored cluster: its BLAS, its member count (members follow the previous cluster's in
/// the member table) and its padded bounds.
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct StoredCluster {
    pub blas: u32,
    pub member_count: u32,
    pub bounds: Box6,
}

/// A package's stored clusters: per TLAS of the view they were made for, its entry; the
/// clusters; the members (indices in their TLAS's instance range), cluster after cluster.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StoredProxyClusters {
    pub instance_count: u64,
    pub tlases: Vec<StoredTlas>,
    pub clusters: Vec<StoredCluster>,
    pub members: Vec<u32>,
    /// Per cluster, where its members start (made by [`decode_section`]).
    member_first: Vec<u64>,
}

/// What [`StoredProxyClusters::tlas_clusters`] found for a TLAS.
#[derive(Clone, Debug, PartialEq)]
pub enum Stored {
    /// The entry matches the TLAS: its clusters.
    Valid(Vec<Cluster>),
    /// The entry was made for another TLAS (its record, instances or the BLAS table differ).
    Stale,
}

impl StoredProxyClusters {
    /// The table of `clusters` (per TLAS of `view`, as [`all_clusters`] makes them).
    pub fn new(view: &HierarchyView<'_>, clusters: &[Vec<Cluster>]) -> StoredProxyClusters {
        use rayon::prelude::*;
        let bh = blases_hash(view);
        let hashes: Vec<u64> = (0..view.tlases.len())
            .into_par_iter()
            .map(|t| tlas_hash(view, t, bh))
            .collect();
        let mut out = StoredProxyClusters {
            instance_count: view.instances.len() as u64,
            ..Default::default()
        };
        for (list, hash) in clusters.iter().zip(hashes) {
            out.push_tlas(hash, list);
        }
        out
    }

    /// The table of every TLAS of `view`: [`StoredProxyClusters::new`] over [`all_clusters`],
    /// the same table, but made a batch of TLASes at a time (in parallel within a batch), each
    /// batch's clusters folded in and dropped before the next: an import holds the flat table
    /// (~6.5 bytes an instance), not every cluster's own member list beside it (issue 48 item
    /// 1).
    pub fn of_view(view: &HierarchyView<'_>) -> StoredProxyClusters {
        Self::of_view_then(view, &mut || {})
    }

    /// [`StoredProxyClusters::of_view`] calling `after_batch` once each batch of TLASes is
    /// made (the import drops the pages of a mapped instance table read so far there:
    /// `StreamSplit::release_instance_pages`).
    pub fn of_view_then(
        view: &HierarchyView<'_>,
        after_batch: &mut dyn FnMut(),
    ) -> StoredProxyClusters {
        use rayon::prelude::*;
        let bh = blases_hash(view);
        let n = view.tlases.len();
        // Room for the most members the table can take (one per instance of every TLAS) and
        // clusters of 8 on average (16 at most; 10-13 on the island and the grid), so it
        // seldom grows by copying; pages never written are never resident.
        let most: usize = view.tlases.iter().map(|t| t.instance_count as usize).sum();
        let clusters = most / (CLUSTER_INSTANCES / 2) + n;
        let mut out = StoredProxyClusters {
            instance_count: view.instances.len() as u64,
            tlases: Vec::with_capacity(n),
            clusters: Vec::with_capacity(clusters),
            members: Vec::with_capacity(most),
            member_first: Vec::with_capacity(clusters),
        };
        // A few TLASes a thread per batch (a large one among small ones does not idle the
        // rest), and at most `BATCH_INSTANCES_PER_THREAD` instances a thread but for a batch of one TLAS: a TLAS's
        // clusters take ~30 bytes an instance while they are made (a large TLAS is made on
        // all threads by the SAH itself).
        let threads = rayon::current_num_threads().max(1);
        let batch = 4 * threads;
        let batch_instances = (threads * BATCH_INSTANCES_PER_THREAD).max(1 << 20);
        let count = |t: usize| view.tlases[t].instance_count as usize;
        let mut first = 0;
        while first < n {
            let mut end = first + 1;
            let mut instances = count(first);
            while end < n && end - first < batch && instances + count(end) <= batch_instances {
                instances += count(end);
                end += 1;
            }
            let made: Vec<(u64, ClusterTable)> = (first..end)
                .into_par_iter()
                .map(|t| (tlas_hash(view, t, bh), tlas_cluster_table(view, t)))
                .collect();
            for (hash, (clusters, members)) in made {
                out.push_table(hash, &clusters, &members);
            }
            after_batch();
            first = end;
        }
        out
    }

    /// Appends a TLAS's entry (`hash`) and its clusters in the table's form
    /// ([`tlas_cluster_table`]).
    fn push_table(&mut self, hash: u64, clusters: &[StoredCluster], members: &[u32]) {
        self.tlases.push(StoredTlas {
            hash,
            first_cluster: self.clusters.len() as u64,
            cluster_count: clusters.len() as u64,
        });
        let mut first = self.members.len() as u64;
        for c in clusters {
            self.member_first.push(first);
            first += u64::from(c.member_count);
        }
        self.clusters.extend_from_slice(clusters);
        self.members.extend_from_slice(members);
    }

    /// Appends a TLAS's entry (`hash`) and its clusters.
    fn push_tlas(&mut self, hash: u64, list: &[Cluster]) {
        self.tlases.push(StoredTlas {
            hash,
            first_cluster: self.clusters.len() as u64,
            cluster_count: list.len() as u64,
        });
        for c in list {
            self.member_first.push(self.members.len() as u64);
            self.clusters.push(StoredCluster {
                blas: c.blas,
                member_count: c.members.len() as u32,
                bounds: c.bounds,
            });
            self.members.extend_from_slice(&c.members);
        }
    }

    /// Whether the table was made for a view of `view`'s shape (TLAS and instance counts): a
    /// table of another shape (another stream split, an element subset) is not one to check
    /// TLAS by TLAS.
    pub fn fits(&self, view: &HierarchyView<'_>) -> bool {
        self.tlases.len() == view.tlases.len() && self.instance_count == view.instances.len() as u64
    }

    /// TLAS `t`'s stored clusters, checked against `view` ([`tlas_hash`] with `blases_hash`,
    /// [`blases_hash`] of `view`) and its ranges (members inside the TLAS, BLASes in range).
    /// The table must [`fit`](Self::fits) `view`.
    pub fn tlas_clusters(&self, view: &HierarchyView<'_>, t: usize, blases_hash: u64) -> Stored {
        let e = self.tlases[t];
        if e.hash != tlas_hash(view, t, blases_hash) {
            return Stored::Stale;
        }
        let count = view.tlases[t].instance_count;
        let first = e.first_cluster as usize;
        let mut out = Vec::with_capacity(e.cluster_count as usize);
        for (k, c) in self.clusters[first..][..e.cluster_count as usize]
            .iter()
            .enumerate()
        {
            let start = self.member_first[first + k] as usize;
            let members = &self.members[start..start + c.member_count as usize];
            if c.blas as usize >= view.blases.len() || members.iter().any(|&m| m >= count) {
                return Stored::Stale;
            }
            out.push(Cluster {
                blas: c.blas,
                bounds: c.bounds,
                members: members.to_vec(),
            });
        }
        Stored::Valid(out)
    }
}

/// The section's bytes: [`SECTION_MAGIC`], the instance, TLAS, cluster and member counts (u64
/// each), the TLAS entries (24 bytes each), the clusters (32 bytes each), the members (u32).
pub fn encode_section(t: &StoredProxyClusters) -> Vec<u8> {
    let mut out = Vec::with_capacity(section_bytes(t));
    let _ = write_section(t, |piece| {
        out.extend_from_slice(piece);
        Ok::<(), std::convert::Infallible>(())
    });
    out
}

/// The length of [`encode_section`]'s bytes.
pub fn section_bytes(t: &StoredProxyClusters) -> usize {
    SECTION_MAGIC.len()
        + 32
        + std::mem::size_of_val(&t.tlases[..])
        + std::mem::size_of_val(&t.clusters[..])
        + std::mem::size_of_val(&t.members[..])
}

/// [`encode_section`]'s bytes handed to `write` piece by piece (a few MiB at most each), so a
/// writer can store the section without a copy of the table beside it.
pub fn write_section<E>(
    t: &StoredProxyClusters,
    mut write: impl FnMut(&[u8]) -> Result<(), E>,
) -> Result<(), E> {
    let mut head = BlobWriter::new(SECTION_MAGIC, 32);
    head.u64(t.instance_count)
        .u64(t.tlases.len() as u64)
        .u64(t.clusters.len() as u64)
        .u64(t.members.len() as u64);
    write(&head.finish())?;
    const PIECE_BYTES: usize = 4 << 20;
    for bytes in [
        bytemuck::cast_slice::<_, u8>(&t.tlases),
        bytemuck::cast_slice(&t.clusters),
        bytemuck::cast_slice(&t.members),
    ] {
        for piece in bytes.chunks(PIECE_BYTES) {
            write(piece)?;
        }
    }
    Ok(())
}

/// Reads what [`encode_section`] wrote; `None` for another magic (another version), a cut or
/// long section, TLAS entries that do not tile the clusters in order, or member counts that do
/// not add up to the member table.
pub fn decode_section(bytes: &[u8]) -> Option<StoredProxyClusters> {
    let mut r = BlobReader::new(bytes, SECTION_MAGIC)?;
    let instance_count = r.u64()?;
    let n_tlases = usize::try_from(r.u64()?).ok()?;
    let n_clusters = usize::try_from(r.u64()?).ok()?;
    let n_members = usize::try_from(r.u64()?).ok()?;
    // Counts checked against the bytes before anything is allocated.
    let need = n_tlases
        .checked_mul(std::mem::size_of::<StoredTlas>())?
        .checked_add(n_clusters.checked_mul(std::mem::size_of::<StoredCluster>())?)?
        .checked_add(n_members.checked_mul(4)?)?;
    if need != r.remaining() {
        return None;
    }
    let tlases: Vec<StoredTlas> = r.pods(n_tlases)?;
    let clusters: Vec<StoredCluster> = r.pods(n_clusters)?;
    let members: Vec<u32> = r.pods(n_members)?;
    r.finish()?;
    let mut next = 0u64;
    for e in &tlases {
        if e.first_cluster != next {
            return None;
        }
        next = next.checked_add(e.cluster_count)?;
    }
    if next != n_clusters as u64 {
        return None;
    }
    let mut member_first = Vec::with_capacity(n_clusters);
    let mut m = 0u64;
    for c in &clusters {
        member_first.push(m);
        m += u64::from(c.member_count);
    }
    (m == n_members as u64).then_some(StoredProxyClusters {
        instance_count,
        tlases,
        clusters,
        members,
        member_first,
    })
}

#[cfg(test)]
mod tests;
