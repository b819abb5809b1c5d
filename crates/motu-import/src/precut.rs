//! Cutting meshes into clusters while parsing (issue 48 item 1).
//!
//! A mesh over the partition bound is only ever stored as clusters. Once the bound is known,
//! [`PrecutGeometry`] queues such a mesh for a cutting thread the moment the parser stores it
//! (`motu_compile::partition::partition_mesh`, the compiler's own cut, on all cores) and the
//! parser goes on; the clusters are appended to the package later, so the compiler makes their
//! records from their shapes ([`motu_compile::StoredClusters`]) instead of writing the whole
//! mesh to the spill file, reading it back and cutting it then: partitioning costs what the
//! geometry it cuts costs and overlaps parsing.
//!
//! The queue is bounded by source-mesh bytes (`cut_queue_bytes`, [`DEFAULT_CUT_QUEUE_BYTES`]):
//! past it the parser appends the oldest mesh's clusters, waiting for them if the cutting
//! thread is behind; the thread sends clusters as it cuts them through a queue of a few, so a
//! mesh is never held whole as clusters. Appends run on the thread that replays the parser's events, in queue
//! order and at points that depend only on the meshes' sizes, so the package is the same on
//! every run (0 bytes: each mesh is cut and appended before its store returns).
//!
//! The bound is known from the start when given (`--max-blas-triangles`); the automatic bound
//! once `auto_bound_settles_at_triangles` triangles were stored. Before that, meshes take the
//! spill file as before; when the bound becomes known, those over it are read back from the
//! spill file (still in the page cache) and queued at once, still during parsing. Mesh
//! records are those the compiler would make itself (same ids, counts, bounds and cluster
//! data; only where clusters lie in the chunks differs): tested against the compile-time path
//! in `tests.rs`.
//!
//! Not used with LOD (a LOD chain needs the whole mesh), `--levels auto` (a baked prototype
//! needs it too) or `--subset` (its scratch package has no spill file).

use motu_compile::partition::Cluster;
use motu_compile::proxy_boxes::{boxes_from_meshes, fan, Box6};
use motu_compile::ClusterShape;
use motu_pack::PackageGeometry;
use motu_scene::{GeometryStore, MeshData, MeshId, MeshLocation, StoreError};
use rayon::prelude::*;
use std::borrow::Cow;
use std::collections::{HashMap, VecDeque};
use std::sync::mpsc::{channel, sync_channel, Receiver, Sender};
use std::sync::{Arc, Mutex, MutexGuard};

/// Chunk group for the clusters of partitioned meshes (and LOD levels).
pub(crate) const CLUSTER_GROUP: u32 = u32::MAX - 2;

/// Marks a scene location of a mesh that was cut while parsing (its whole data is not kept).
const CUT_BIT: u64 = 1 << 62;

/// Source-mesh bytes queued for the cutting thread at most (besides the newest mesh, which is
/// queued whatever its size): with [`CLUSTERS_IN_FLIGHT`] clusters, the memory overlapping
/// costs.
pub const DEFAULT_CUT_QUEUE_BYTES: u64 = 32 << 20;

/// A [`GeometryStore`] over the import's [`PackageGeometry`] that cuts meshes over the
/// partition bound as they are stored. Clones share their state.
#[derive(Clone)]
pub(crate) struct PrecutGeometry {
    geometry: PackageGeometry,
    state: Arc<Mutex<State>>,
}

/// A mesh for the cutting thread.
struct Job {
    data: MeshData,
    bound: u32,
}

/// What the cutting thread sends back, in queue order: each mesh's clusters as they are cut
/// (with their proxy boxes when asked for), then the milliseconds its cut took.
enum Cut {
    Cluster(Cluster, Option<Vec<Box6>>),
    Done(f64),
}

/// A cluster's proxy boxes as a BLAS of it alone has them (`motu_compile::proxy_boxes`'s
/// `blas_boxes` over one mesh: the same operations on the same data, so the same bits): made
/// from the cluster in memory, they spare the import reading it back from the package.
#[derive(Clone, Debug)]
pub(crate) struct ClusterBoxes {
    pub chunk: u32,
    pub vertex_count: u32,
    pub triangle_count: u32,
    pub boxes: Vec<Box6>,
}

/// A cluster's boxes as a BLAS of it alone has them (fan by its triangles).
fn cluster_boxes(c: &Cluster) -> Vec<Box6> {
    let f = fan(c.data.triangle_count() as u32) as usize;
    boxes_from_meshes(&[(&c.data.positions[..], &c.data.indices[..])], f)
}

/// Clusters cut but not yet appended, at most (each up to a cluster: ~2.5 MiB at 2^16
/// triangles), so a mesh far larger than the queue is never held as clusters whole.
const CLUSTERS_IN_FLIGHT: usize = 8;

/// A queued mesh: its id, bound and size.
struct Pending {
    id: MeshId,
    bound: u32,
    triangles: u64,
    bytes: u64,
}

/// The cutting thread and its two queues (jobs in, clusters out, both in queue order).
struct Cutter {
    jobs: Option<Sender<Job>>,
    done: Option<Receiver<Cut>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Cutter {
    fn spawn(boxes: bool) -> Result<Self, StoreError> {
        let (jobs, job_rx) = channel::<Job>();
        let (done_tx, done) = sync_channel::<Cut>(CLUSTERS_IN_FLIGHT);
        let thread = std::thread::Builder::new()
            .name("motu-cut".into())
            .spawn(move || {
                // Clusters whose boxes are made together, on all cores.
                let batch = rayon::current_num_threads().clamp(1, CLUSTERS_IN_FLIGHT);
                let mut cut: Vec<Cluster> = Vec::with_capacity(batch);
                let send = |cut: &mut Vec<Cluster>| -> Result<(), ()> {
                    let made: Vec<Option<Vec<Box6>>> = if boxes {
                        cut.par_iter().map(|c| Some(cluster_boxes(c))).collect()
                    } else {
                        vec![None; cut.len()]
                    };
                    for (c, b) in cut.drain(..).zip(made) {
                        done_tx.send(Cut::Cluster(c, b)).map_err(|_| ())?;
                    }
                    Ok(())
                };
                for job in job_rx {
                    let t = std::time::Instant::now();
                    let sent = motu_compile::partition::partition_mesh(
                        &job.data,
                        job.bound,
                        &mut |c: Cluster| {
                            cut.push(c);
                            if cut.len() < batch {
                                return Ok(());
                            }
                            send(&mut cut)
                        },
                    )
                    .and_then(|()| send(&mut cut));
                    drop(job.data);
                    let ms = t.elapsed().as_secs_f64() * 1e3;
                    // The receiver is gone: the import stopped.
                    if sent.is_err() || done_tx.send(Cut::Done(ms)).is_err() {
                        return;
                    }
                }
            })?;
        Ok(Self {
            jobs: Some(jobs),
            done: Some(done),
            thread: Some(thread),
        })
    }
}

impl Drop for Cutter {
    fn drop(&mut self) {
        // No more jobs, and no one to take clusters: the thread ends after its current cut.
        self.jobs = None;
        self.done = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

struct State {
    /// The bound clusters are cut at, once known.
    bound: Option<u32>,
    /// `(stored triangles, bound)`: the automatic bound, known once that many were stored.
    settles: Option<(u64, u32)>,
    stored_triangles: u64,
    /// Meshes stored whole (spilled) before the bound was known that may be over it.
    waiting: Vec<(MeshId, MeshLocation, usize)>,
    /// Per source mesh cut: the bound and its clusters' shapes and locations, in cut order.
    cut: HashMap<u32, (u32, Vec<(ClusterShape, MeshLocation)>)>,
    /// Whether clusters get their proxy boxes as they are cut, and those made, by cluster
    /// location, then by mesh record once the compiler numbered them ([`Self::clusters`]).
    make_boxes: bool,
    boxes: HashMap<(u64, u64), Vec<Box6>>,
    record_boxes: HashMap<u32, ClusterBoxes>,
    /// Source-mesh bytes queued at most (0: each mesh is cut before its store returns).
    queue_bytes: u64,
    /// Meshes queued for the cutting thread, oldest first, and their bytes.
    pending: VecDeque<Pending>,
    pending_bytes: u64,
    cutter: Option<Cutter>,
    /// Time the cutting thread spent cutting, and the time the parser waited for it.
    cut_ms: f64,
    wait_ms: f64,
    cut_triangles: u64,
}

impl PrecutGeometry {
    /// `bound`: the partition bound when known now; `settles`: `(after_triangles, bound)` for
    /// the automatic bound; `queue_bytes`: source-mesh bytes the cutting thread may lag behind
    /// the parser by (0: cut each mesh before its store returns).
    pub fn new(
        geometry: PackageGeometry,
        bound: Option<u32>,
        settles: Option<(u64, u32)>,
        queue_bytes: u64,
    ) -> Self {
        Self {
            geometry,
            state: Arc::new(Mutex::new(State {
                bound,
                settles,
                stored_triangles: 0,
                waiting: Vec::new(),
                cut: HashMap::new(),
                make_boxes: false,
                boxes: HashMap::new(),
                record_boxes: HashMap::new(),
                queue_bytes,
                pending: VecDeque::new(),
                pending_bytes: 0,
                cutter: None,
                cut_ms: 0.0,
                wait_ms: 0.0,
                cut_triangles: 0,
            })),
        }
    }

    fn lock(&self) -> Result<MutexGuard<'_, State>, StoreError> {
        self.state
            .lock()
            .map_err(|_| "the cutting store's lock was poisoned".into())
    }

    /// Queues `data` (source mesh `id`) for the cutting thread at `bound`, then appends the
    /// clusters of the oldest queued meshes while more than the queue's bytes wait. Clusters
    /// are appended on this (the parser's) thread, in queue order and at points that depend
    /// only on the meshes' sizes, so the package is the same on every run.
    fn cut(
        &self,
        st: &mut State,
        id: MeshId,
        data: MeshData,
        bound: u32,
    ) -> Result<(), StoreError> {
        if st.cutter.is_none() {
            st.cutter = Some(Cutter::spawn(st.make_boxes)?);
        }
        let bytes = data.size_bytes();
        let triangles = data.triangle_count() as u64;
        let sent = st
            .cutter
            .as_ref()
            .and_then(|c| c.jobs.as_ref())
            .is_some_and(|jobs| jobs.send(Job { data, bound }).is_ok());
        if !sent {
            return Err("the cutting thread stopped".into());
        }
        st.pending.push_back(Pending {
            id,
            bound,
            triangles,
            bytes,
        });
        st.pending_bytes += bytes;
        while st.pending_bytes > st.queue_bytes && (st.pending.len() > 1 || st.queue_bytes == 0) {
            self.retire(st)?;
        }
        Ok(())
    }

    /// Appends the oldest queued mesh's clusters to the package as they come.
    fn retire(&self, st: &mut State) -> Result<(), StoreError> {
        let Some(p) = st.pending.pop_front() else {
            return Ok(());
        };
        st.pending_bytes -= p.bytes;
        let mut placed = Vec::new();
        loop {
            let t = std::time::Instant::now();
            let next = st
                .cutter
                .as_ref()
                .and_then(|c| c.done.as_ref())
                .ok_or("no cutting thread")?
                .recv()
                .map_err(|_| "the cutting thread stopped")?;
            st.wait_ms += t.elapsed().as_secs_f64() * 1e3;
            let (c, boxes) = match next {
                Cut::Cluster(c, boxes) => (c, boxes),
                Cut::Done(ms) => {
                    st.cut_ms += ms;
                    break;
                }
            };
            let at =
                self.geometry
                    .append_mesh_mapped(CLUSTER_GROUP, &c.data, Some(&c.primitive_map))?;
            let shape = ClusterShape {
                vertex_count: c.data.positions.len() as u32,
                triangle_count: c.data.triangle_count() as u32,
                has_normals: c.data.normals.is_some(),
                bounds: c.bounds,
            };
            if let Some(b) = boxes {
                st.boxes.insert((at.a, at.b), b);
            }
            placed.push((shape, at));
        }
        st.cut.insert(p.id.0, (p.bound, placed));
        st.cut_triangles += p.triangles;
        Ok(())
    }

    /// Appends the clusters of every queued mesh and stops the cutting thread: call once the
    /// parser is done, before [`Self::clusters`].
    pub fn finish(&self) -> Result<(), StoreError> {
        let mut st = self.lock()?;
        while !st.pending.is_empty() {
            self.retire(&mut st)?;
        }
        st.cutter = None;
        Ok(())
    }

    /// The automatic bound became known: cut the spilled meshes over it.
    fn catch_up(&self, st: &mut State, bound: u32) -> Result<(), StoreError> {
        self.geometry.raise_spill_bound(u64::from(bound));
        for (id, at, triangles) in std::mem::take(&mut st.waiting) {
            if triangles > bound as usize {
                let data = self.geometry.load(id, at)?;
                self.cut(st, id, data, bound)?;
            }
        }
        Ok(())
    }

    /// The clusters of source mesh `m` cut at `bound`, their records numbered from `first`
    /// (each record's location is put in `locations`); `None` if `m` was not cut at `bound`.
    pub fn clusters(
        &self,
        m: MeshId,
        bound: u32,
        first: u32,
        locations: &mut HashMap<u32, MeshLocation>,
    ) -> Option<Vec<ClusterShape>> {
        let mut st = self.state.lock().ok()?;
        let st = &mut *st;
        let (b, clusters) = st.cut.get(&m.0)?;
        if *b != bound {
            return None;
        }
        for (k, (shape, at)) in clusters.iter().enumerate() {
            let record = first + k as u32;
            locations.insert(record, *at);
            // Moved, not copied: the compiler numbers a mesh's clusters once (a second call
            // finds none, and the import makes those boxes from the package).
            if let Some(boxes) = st.boxes.remove(&(at.a, at.b)) {
                let made = ClusterBoxes {
                    chunk: at.a as u32,
                    vertex_count: shape.vertex_count,
                    triangle_count: shape.triangle_count,
                    boxes,
                };
                st.record_boxes.insert(record, made);
            }
        }
        Some(clusters.iter().map(|c| c.0).collect())
    }

    /// Clusters get their proxy boxes as they are cut ([`Self::take_record_boxes`]).
    pub fn with_boxes(self) -> Self {
        if let Ok(mut st) = self.state.lock() {
            st.make_boxes = true;
        }
        self
    }

    /// The proxy boxes of the clusters [`Self::clusters`] numbered, by mesh record.
    pub fn take_record_boxes(&self) -> HashMap<u32, ClusterBoxes> {
        self.state.lock().map_or_else(
            |_| HashMap::new(),
            |mut st| {
                st.boxes = HashMap::new();
                std::mem::take(&mut st.record_boxes)
            },
        )
    }

    /// Milliseconds the cutting thread spent cutting, milliseconds the parser waited for it,
    /// and the triangles cut (during parsing).
    pub fn cut_report(&self) -> (f64, f64, u64) {
        self.state.lock().map_or((0.0, 0.0, 0), |st| {
            (st.cut_ms, st.wait_ms, st.cut_triangles)
        })
    }
}

impl GeometryStore for PrecutGeometry {
    fn store(
        &mut self,
        id: MeshId,
        group: u32,
        data: &MeshData,
    ) -> Result<MeshLocation, StoreError> {
        self.store_cow(id, group, Cow::Borrowed(data))
    }

    /// The parser's meshes go to the cutting thread as they are (a copy was a second fresh
    /// set of pages for every triangle cut: issue 48 item 1).
    fn store_owned(
        &mut self,
        id: MeshId,
        group: u32,
        data: MeshData,
    ) -> Result<MeshLocation, StoreError> {
        self.store_cow(id, group, Cow::Owned(data))
    }

    fn load(&self, id: MeshId, at: MeshLocation) -> Result<MeshData, StoreError> {
        if at.a & CUT_BIT != 0 {
            return Err(format!(
                "{id} was cut into clusters while parsing; its whole data is not kept"
            )
            .into());
        }
        self.geometry.load(id, at)
    }
}

impl PrecutGeometry {
    /// [`GeometryStore::store`], cutting a mesh over the bound on the cutting thread (a
    /// borrowed mesh copied for it) and storing the others whole.
    fn store_cow(
        &mut self,
        id: MeshId,
        group: u32,
        data: Cow<'_, MeshData>,
    ) -> Result<MeshLocation, StoreError> {
        let this = self.clone();
        let mut st = this.lock()?;
        let triangles = data.triangle_count();
        st.stored_triangles += triangles as u64;
        if st.bound.is_none() {
            if let Some((after, bound)) = st.settles {
                if st.stored_triangles >= after {
                    st.bound = Some(bound);
                    this.catch_up(&mut st, bound)?;
                }
            }
        }
        if let Some(bound) = st.bound.filter(|&b| triangles > b as usize) {
            this.cut(&mut st, id, data.into_owned(), bound)?;
            return Ok(MeshLocation {
                a: CUT_BIT | u64::from(id.0),
                b: 0,
            });
        }
        let at = self.geometry.store(id, group, &data)?;
        if st.bound.is_none() && PackageGeometry::is_spilled(at) {
            st.waiting.push((id, at, triangles));
        }
        Ok(at)
    }
}

#[cfg(test)]
pub(crate) mod tests;
