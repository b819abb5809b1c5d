//! Cutting meshes into clusters while parsing (issue 48 item 1).
//!
//! A mesh over the partition bound is only ever stored as clusters. Once the bound is known,
//! [`PrecutGeometry`] cuts such a mesh the moment the parser stores it
//! (`motu_compile::partition::partition_mesh`, the compiler's own cut, on all cores) and appends
//! the clusters to the package, so the compiler makes their records from their shapes
//! ([`motu_compile::StoredClusters`]) instead of writing the whole mesh to the spill file,
//! reading it back and cutting it then: partitioning costs what the geometry it cuts costs and
//! runs beside the parser's worker threads.
//!
//! The bound is known from the start when given (`--max-blas-triangles`); the automatic bound
//! once `auto_bound_settles_at_triangles` triangles were stored. Before that, meshes take the
//! spill file as before; when the bound becomes known, those over it are read back from the
//! spill file (still in the page cache) and cut at once, still during parsing. Every step
//! runs on the thread that replays the parser's events in document order, so the package is
//! the same on every run. Mesh records are those the compiler would make itself (same ids,
//! counts, bounds and cluster data; only where clusters lie in the chunks differs): tested
//! against the compile-time path in `tests.rs`.
//!
//! Not used with LOD (a LOD chain needs the whole mesh), `--levels auto` (a baked prototype
//! needs it too) or `--subset` (its scratch package has no spill file).

use motu_compile::ClusterShape;
use motu_pack::PackageGeometry;
use motu_scene::{GeometryStore, MeshData, MeshId, MeshLocation, StoreError};
use std::collections::HashMap;
use std::sync::{Arc, Mutex, MutexGuard};

/// Chunk group for the clusters of partitioned meshes (and LOD levels).
pub(crate) const CLUSTER_GROUP: u32 = u32::MAX - 2;

/// Marks a scene location of a mesh that was cut while parsing (its whole data is not kept).
const CUT_BIT: u64 = 1 << 62;

/// A [`GeometryStore`] over the import's [`PackageGeometry`] that cuts meshes over the
/// partition bound as they are stored. Clones share their state.
#[derive(Clone)]
pub(crate) struct PrecutGeometry {
    geometry: PackageGeometry,
    state: Arc<Mutex<State>>,
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
    /// Time spent cutting (for the import's report).
    cut_ms: f64,
    cut_triangles: u64,
}

impl PrecutGeometry {
    /// `bound`: the partition bound when known now; `settles`: `(after_triangles, bound)` for
    /// the automatic bound.
    pub fn new(geometry: PackageGeometry, bound: Option<u32>, settles: Option<(u64, u32)>) -> Self {
        Self {
            geometry,
            state: Arc::new(Mutex::new(State {
                bound,
                settles,
                stored_triangles: 0,
                waiting: Vec::new(),
                cut: HashMap::new(),
                cut_ms: 0.0,
                cut_triangles: 0,
            })),
        }
    }

    fn lock(&self) -> Result<MutexGuard<'_, State>, StoreError> {
        self.state
            .lock()
            .map_err(|_| "the cutting store's lock was poisoned".into())
    }

    /// Cuts `data` (source mesh `id`) at `bound` and appends its clusters to the package.
    fn cut(
        &self,
        st: &mut State,
        id: MeshId,
        data: &MeshData,
        bound: u32,
    ) -> Result<(), StoreError> {
        let t = std::time::Instant::now();
        let mut clusters = Vec::new();
        motu_compile::partition::partition_mesh(
            data,
            bound,
            &mut |c: motu_compile::partition::Cluster| {
                let at = self.geometry.append_mesh_mapped(
                    CLUSTER_GROUP,
                    &c.data,
                    Some(&c.primitive_map),
                )?;
                let shape = ClusterShape {
                    vertex_count: c.data.positions.len() as u32,
                    triangle_count: c.data.triangle_count() as u32,
                    has_normals: c.data.normals.is_some(),
                    bounds: c.bounds,
                };
                clusters.push((shape, at));
                Ok::<(), motu_pack::PackError>(())
            },
        )?;
        st.cut.insert(id.0, (bound, clusters));
        st.cut_ms += t.elapsed().as_secs_f64() * 1e3;
        st.cut_triangles += data.triangle_count() as u64;
        Ok(())
    }

    /// The automatic bound became known: cut the spilled meshes over it.
    fn catch_up(&self, st: &mut State, bound: u32) -> Result<(), StoreError> {
        self.geometry.raise_spill_bound(u64::from(bound));
        for (id, at, triangles) in std::mem::take(&mut st.waiting) {
            if triangles > bound as usize {
                let data = self.geometry.load(id, at)?;
                self.cut(st, id, &data, bound)?;
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
        let st = self.state.lock().ok()?;
        let (b, clusters) = st.cut.get(&m.0)?;
        if *b != bound {
            return None;
        }
        for (k, (_, at)) in clusters.iter().enumerate() {
            locations.insert(first + k as u32, *at);
        }
        Some(clusters.iter().map(|c| c.0).collect())
    }

    /// Milliseconds spent cutting and the triangles cut (during parsing).
    pub fn cut_report(&self) -> (f64, u64) {
        self.state
            .lock()
            .map_or((0.0, 0), |st| (st.cut_ms, st.cut_triangles))
    }
}

impl GeometryStore for PrecutGeometry {
    fn store(
        &mut self,
        id: MeshId,
        group: u32,
        data: &MeshData,
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
            this.cut(&mut st, id, data, bound)?;
            return Ok(MeshLocation {
                a: CUT_BIT | u64::from(id.0),
                b: 0,
            });
        }
        let at = self.geometry.store(id, group, data)?;
        if st.bound.is_none() && PackageGeometry::is_spilled(at) {
            st.waiting.push((id, at, triangles));
        }
        Ok(at)
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

#[cfg(test)]
pub(crate) mod tests;
