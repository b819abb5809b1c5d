//! Mesh records: a prototype mesh's record, made from its source data (baked copies, LOD levels,
//! clusters) or taken from the caller's stored cut, and its material flags.

use crate::partition::{partition_mesh, Cluster};
use crate::tables::next_id;
use crate::CompileError;
use motu_abi::{
    MeshRecord, FLAG_HAS_NORMALS, FLAG_HAS_UVS, FLAG_NEEDS_ANY_HIT, FLAG_PRIMITIVE_MAP, NONE_U32,
};
use motu_scene::{Aabb, MeshData, MeshId, PrototypeId, Scene};

use super::{empty_mesh_record, Emitter};

impl Emitter<'_, '_, '_, '_> {
    pub(super) fn mesh_element(&self, p: PrototypeId, j: usize) -> u32 {
        let scene = self.plan.scene;
        if p == Scene::ROOT {
            scene.root_mesh_elements().get(j).map_or(NONE_U32, |e| e.0)
        } else {
            scene.prototype(p).element.0
        }
    }

    /// The record of source mesh `m` (whole, LOD 0), as it is in the scene.
    pub(super) fn source_record(&self, p: PrototypeId, j: usize, m: MeshId) -> MeshRecord {
        let info = self.plan.scene.mesh(m);
        let mut flags = self.material_flags(info.material.0);
        if info.has_normals {
            flags |= FLAG_HAS_NORMALS;
        }
        if info.has_uvs {
            flags |= FLAG_HAS_UVS;
        }
        MeshRecord {
            source_mesh: m.0,
            lod: 0,
            material: info.material.0,
            flags,
            vertex_count: info.vertex_count,
            triangle_count: info.triangle_count,
            element: self.mesh_element(p, j),
            ..empty_mesh_record(&info.bounds)
        }
    }

    pub(super) fn record_for(
        &mut self,
        p: PrototypeId,
        j: usize,
        m: MeshId,
    ) -> Result<u32, CompileError> {
        let r = self.record_of_mesh[m.index()];
        if r != NONE_U32 {
            return Ok(r);
        }
        let rec = self.source_record(p, j, m);
        let id = next_id(self.out.meshes.len(), "meshes")?;
        self.out.meshes.push(rec);
        self.record_of_mesh[m.index()] = id;
        Ok(id)
    }

    /// The partitioner's bound: triangles per triangle BLAS.
    pub(super) fn bound(&self) -> u32 {
        self.plan.opts.blas_triangle_bound()
    }

    pub(super) fn load_source(&mut self, m: MeshId) -> Result<MeshData, CompileError> {
        let t = std::time::Instant::now();
        let data = (self.load)(m).map_err(|source| CompileError::MeshLoad { mesh: m.0, source })?;
        self.out.report.phases.load_ms += t.elapsed().as_secs_f64() * 1e3;
        let info = self.plan.scene.mesh(m);
        if data.triangle_count() != info.triangle_count as usize
            || data.positions.len() != info.vertex_count as usize
        {
            return Err(CompileError::Mesh {
                mesh: m.0,
                reason: format!(
                    "stored data has {} vertices and {} triangles, the scene says {} and {}",
                    data.positions.len(),
                    data.triangle_count(),
                    info.vertex_count,
                    info.triangle_count
                ),
            });
        }
        data.validate()
            .map_err(|reason| CompileError::Mesh { mesh: m.0, reason })?;
        Ok(data)
    }

    /// Compiled mesh records for `data` (source mesh `m` at LOD `lod`, whose record template
    /// is `template`): one record handed to the sink when within the bound, else one per
    /// spatial cluster with its primitive map. `base_map` maps `data`'s triangles to the source
    /// mesh's when they are not the same (baked copies); cluster maps compose with it. Returns
    /// the records `(first, count)`.
    pub(super) fn made_records(
        &mut self,
        m: MeshId,
        template: &MeshRecord,
        lod: u32,
        data: &MeshData,
        base_map: Option<&[u32]>,
    ) -> Result<(u32, u32), CompileError> {
        let first = next_id(self.out.meshes.len(), "meshes")?;
        let bound = self.bound();
        let mut flags = template.flags & !(FLAG_HAS_NORMALS | FLAG_PRIMITIVE_MAP);
        if data.normals.is_some() {
            flags |= FLAG_HAS_NORMALS;
        }
        let meshes = &mut self.out.meshes;
        let sink = &mut *self.sink;
        let started = std::time::Instant::now();
        let mut sink_ms = 0.0;
        let mut push = |data: &MeshData, map: Option<&[u32]>, bounds: Aabb| {
            let id = next_id(meshes.len(), "meshes")?;
            let map_flag = if map.is_some() { FLAG_PRIMITIVE_MAP } else { 0 };
            meshes.push(MeshRecord {
                source_mesh: m.0,
                lod,
                flags: flags | map_flag,
                vertex_count: data.positions.len() as u32,
                triangle_count: data.triangle_count() as u32,
                bounds_min: bounds.min,
                bounds_max: bounds.max,
                ..*template
            });
            let t = std::time::Instant::now();
            let r = sink(id, data, map).map_err(|source| CompileError::Sink {
                mesh_record: id,
                source,
            });
            sink_ms += t.elapsed().as_secs_f64() * 1e3;
            r
        };
        if data.triangle_count() <= bound as usize {
            push(data, base_map, data.bounds())?;
        } else {
            let _span = tracing::debug_span!(
                "partition",
                mesh = m.0,
                lod,
                triangles = data.triangle_count()
            )
            .entered();
            partition_mesh(data, bound, &mut |c: Cluster| match base_map {
                Some(base) => {
                    let map: Vec<u32> = c.primitive_map.iter().map(|&t| base[t as usize]).collect();
                    push(&c.data, Some(&map), c.bounds)
                }
                None => push(&c.data, Some(&c.primitive_map), c.bounds),
            })?;
            self.out.report.partitioned_meshes += 1;
            self.out.report.partition_clusters +=
                u64::from(next_id(meshes.len(), "meshes")? - first);
        }
        let phases = &mut self.out.report.phases;
        phases.sink_ms += sink_ms;
        if data.triangle_count() > bound as usize {
            phases.partition_ms += started.elapsed().as_secs_f64() * 1e3 - sink_ms;
        }
        let count = next_id(self.out.meshes.len(), "meshes")? - first;
        Ok((first, count))
    }

    /// The records of source mesh `m` (over the bound, LOD 0, not baked) from clusters its
    /// caller cut and stored already ([`crate::StoredClusters`]): the records
    /// [`Self::made_records`] would make, field for field, or `None` if there are none.
    pub(super) fn stored_records(
        &mut self,
        m: MeshId,
        template: &MeshRecord,
    ) -> Result<Option<(u32, u32)>, CompileError> {
        let first = next_id(self.out.meshes.len(), "meshes")?;
        let bound = self.bound();
        let Some(shapes) = (self.stored)(m, bound, first) else {
            return Ok(None);
        };
        let base = template.flags & !(FLAG_HAS_NORMALS | FLAG_PRIMITIVE_MAP);
        for c in &shapes {
            next_id(self.out.meshes.len(), "meshes")?;
            let normals = if c.has_normals { FLAG_HAS_NORMALS } else { 0 };
            self.out.meshes.push(MeshRecord {
                source_mesh: m.0,
                lod: 0,
                flags: base | normals | FLAG_PRIMITIVE_MAP,
                vertex_count: c.vertex_count,
                triangle_count: c.triangle_count,
                bounds_min: c.bounds.min,
                bounds_max: c.bounds.max,
                ..*template
            });
        }
        let count = next_id(self.out.meshes.len(), "meshes")? - first;
        self.out.report.partitioned_meshes += 1;
        self.out.report.partition_clusters += u64::from(count);
        Ok(Some((first, count)))
    }

    pub(super) fn material_flags(&self, material: u32) -> u32 {
        match self.plan.scene.materials().get(material as usize) {
            Some(mat) if mat.opacity < 1.0 || mat.alpha_texture.is_some() => FLAG_NEEDS_ANY_HIT,
            _ => 0,
        }
    }
}
