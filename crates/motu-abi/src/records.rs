//! The table records. All are `Pod`, 16-byte multiples, with explicit padding, so std430 GLSL
//! structs have identical offsets (checked by `glsl::tests`).

use bytemuck::{Pod, Zeroable};

/// A sentinel for "none" in 32-bit index fields.
pub const NONE_U32: u32 = u32::MAX;
/// A sentinel for "none" in 64-bit offset fields.
pub const NONE_U64: u64 = u64::MAX;

/// The identity as a row-major 3×4 (`InstanceRecord::tlas_from_blas`).
pub const IDENTITY_3X4: [f32; 12] = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0];

/// Kinds of BLAS.
pub const BLAS_TRIANGLES: u32 = 0;
pub const BLAS_AABBS: u32 = 1;

/// Kinds of programmable instance.
pub const PI_TLAS: u32 = 0;
pub const PI_LOD_SELECTOR: u32 = 1;

/// Flag bits of [`InstanceRecord::flags`] and [`MeshRecord::flags`].
pub const FLAG_NEEDS_ANY_HIT: u32 = 1; // alpha-tested: triangles may not be forced opaque
pub const FLAG_HAS_NORMALS: u32 = 2;
pub const FLAG_HAS_UVS: u32 = 4;
/// [`MeshRecord::flags`] only: the mesh is a cluster of a partitioned source mesh (or LOD
/// level) and `primitive_map_offset` points at its `u32` table from cluster triangle to source
/// triangle. Hit records name the mapped (source) primitive.
pub const FLAG_PRIMITIVE_MAP: u32 = 8;

#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct TlasRecord {
    pub instance_base: u32,
    pub instance_count: u32,
    /// Even: 0 for the root.
    pub level: u32,
    /// The element this TLAS belongs to, or `NONE_U32` when shared by several; a PI into a
    /// TLAS of an unselected element is dropped by `--subset`.
    pub element: u32,
    /// Bounds in this TLAS's space.
    pub bounds_min: [f32; 3],
    /// 0 in a package (reserved). A full GPU build sets it to the number of trailing
    /// instances (AABB instances of at most [`BOX_LIST_CAPACITY`] PIs in all) that it leaves
    /// out of the hardware TLAS: the traversal shader tests their boxes itself (a box list).
    pub box_list_instances: u32,
    pub bounds_max: [f32; 3],
    pub _pad1: u32,
}

impl TlasRecord {
    /// Its instance records' indices in the instance table (computed in `usize`: the sum of
    /// two `u32`s can pass `u32::MAX` in a corrupt table, which a reader then rejects by
    /// range, not by overflow).
    pub fn instance_range(&self) -> std::ops::Range<usize> {
        let base = self.instance_base as usize;
        base..base + self.instance_count as usize
    }
}

/// The most programmable instances a TLAS's box list may hold ([`TlasRecord::box_list_instances`]):
/// raygen slab-tests each of them on every first walk of that TLAS, so only a few (the pieces
/// of a split root, a handful of PIs beside a TLAS's own instances) are worth taking out of the
/// hardware walk, where each box a ray crosses costs an intersection and an any-hit call.
pub const BOX_LIST_CAPACITY: u32 = 16;

#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct InstanceRecord {
    /// Row-major 3×4 (the `VkTransformMatrixKHR` layout).
    pub tlas_from_blas: [f32; 12],
    pub blas: u32,
    pub flags: u32,
    /// The element this placement belongs to (root-level items always carry one), or
    /// `NONE_U32` below the root where the parent decides; `--subset` filters on it.
    pub element: u32,
    pub _pad: u32,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct BlasRecord {
    /// `BLAS_TRIANGLES` or `BLAS_AABBS`.
    pub kind: u32,
    /// First entry in the geometry table (triangles) or the PI table (AABBs).
    pub item_base: u32,
    pub item_count: u32,
    /// Odd.
    pub level: u32,
    pub bounds_min: [f32; 3],
    /// Total triangles (triangle BLAS) or AABBs.
    pub primitive_count: u32,
    pub bounds_max: [f32; 3],
    pub _pad: u32,
}

impl BlasRecord {
    /// Its bounds as one box, `[min x, min y, min z, max x, max y, max z]` (the layout of
    /// `VkAabbPositionsKHR`).
    pub fn bounds_box(&self) -> [f32; 6] {
        let (a, b) = (self.bounds_min, self.bounds_max);
        [a[0], a[1], a[2], b[0], b[1], b[2]]
    }
}

/// Geometry `j` of a triangle BLAS is `geometries[item_base + j]`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct GeometryRecord {
    /// Index into the compiled mesh table.
    pub mesh: u32,
    pub _pad: [u32; 3],
}

/// A programmable instance: an AABB in its BLAS that continues traversal elsewhere.
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct PiRecord {
    /// Transforms a ray from the BLAS's space into the child's space (stored inverted so no
    /// shader ever inverts a matrix).
    pub child_from_parent: [f32; 12],
    pub aabb_min: [f32; 3],
    /// `PI_TLAS` or `PI_LOD_SELECTOR`.
    pub kind: u32,
    pub aabb_max: [f32; 3],
    /// A TLAS id or a LOD-selector id, by `kind`.
    pub target: u32,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct LodSelectorRecord {
    /// Bounding sphere in the selector's space, used for projected size.
    pub center: [f32; 3],
    pub radius: f32,
    /// Levels are `lod_levels[level_base .. level_base + level_count]` (TLAS ids), finest first.
    pub level_base: u32,
    pub level_count: u32,
    pub source_mesh: u32,
    pub _pad: u32,
}

/// A compiled mesh: positions (`[f32; 3]`, tightly packed) and `u32` triangle indices, stored
/// in package chunks ready for upload. A source mesh over the compiler's BLAS bound becomes
/// several compiled meshes (spatial clusters), each with the same `source_mesh` and a
/// primitive map, so hits still name the source mesh and its primitive.
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct MeshRecord {
    /// The mesh id in the imported scene (stable across compile settings).
    pub source_mesh: u32,
    /// 0 = the source mesh itself.
    pub lod: u32,
    pub material: u32,
    pub flags: u32,
    pub vertex_count: u32,
    pub triangle_count: u32,
    /// Package chunk holding the data.
    pub chunk: u32,
    pub element: u32,
    pub positions_offset: u64,
    pub indices_offset: u64,
    /// `NONE_U64` when the mesh has no normals.
    pub normals_offset: u64,
    /// With [`FLAG_PRIMITIVE_MAP`]: the cluster's `u32` per triangle (its triangle index in
    /// the source mesh, or in the LOD level's mesh when `lod > 0`); else `NONE_U64`.
    pub primitive_map_offset: u64,
    /// `[f32; 2]` per vertex; meaningful only with `FLAG_HAS_UVS`.
    pub uvs_offset: u64,
    pub _pad_uv: u64,
    pub bounds_min: [f32; 3],
    pub _pad1: u32,
    pub bounds_max: [f32; 3],
    pub _pad2: u32,
}

/// What a surface looks like (resolved at import: constant, scale and mix textures are folded
/// into the constants; image textures are referenced by index).
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct MaterialRecord {
    /// Linear RGB reflectance (multiplied by the base-colour texture where there is one).
    pub base_color: [f32; 3],
    /// Constant coverage (`float alpha` / `opacity`): below `ALPHA_CUTOFF` the surface is cut out.
    pub opacity: f32,
    /// Emitted radiance (area lights), linear RGB.
    pub emission: [f32; 3],
    /// Perceptual roughness in [0, 1].
    pub roughness: f32,
    /// 0 dielectric, 1 metal.
    pub metallic: f32,
    /// Index into the texture table, or `NONE_U32`.
    pub base_color_texture: u32,
    /// Coverage texture (its first channel, or alpha where it has one), or `NONE_U32`.
    pub alpha_texture: u32,
    pub _pad: u32,
}

impl Default for MaterialRecord {
    fn default() -> Self {
        Self {
            base_color: [0.5; 3],
            opacity: 1.0,
            emission: [0.0; 3],
            roughness: 0.5,
            metallic: 0.0,
            base_color_texture: NONE_U32,
            alpha_texture: NONE_U32,
            _pad: 0,
        }
    }
}

/// The inverse of a row-major 3×4 affine transform, computed in f64 (adjugate over the
/// determinant); `None` when the determinant is not finite or below 1e-30 in magnitude. Entries
/// may overflow f32 to infinity: callers that need finite matrices check (the CPU tracer's
/// `ray::invert` does). The one inverse of the instance-LOD rewrite and the CPU tracer.
pub fn invert_3x4(m: &[f32; 12]) -> Option<[f32; 12]> {
    let a = |r: usize, c: usize| f64::from(m[4 * r + c]);
    let det = a(0, 0) * (a(1, 1) * a(2, 2) - a(1, 2) * a(2, 1))
        - a(0, 1) * (a(1, 0) * a(2, 2) - a(1, 2) * a(2, 0))
        + a(0, 2) * (a(1, 0) * a(2, 1) - a(1, 1) * a(2, 0));
    if !det.is_finite() || det.abs() < 1e-30 {
        return None;
    }
    let inv_det = 1.0 / det;
    let mut l = [[0f64; 3]; 3];
    for (r, row) in l.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            // Adjugate: cofactor of (c, r).
            let (r0, r1) = ((c + 1) % 3, (c + 2) % 3);
            let (c0, c1) = ((r + 1) % 3, (r + 2) % 3);
            *v = (a(r0, c0) * a(r1, c1) - a(r0, c1) * a(r1, c0)) * inv_det;
        }
    }
    let t = [a(0, 3), a(1, 3), a(2, 3)];
    let mut out = [0f32; 12];
    for r in 0..3 {
        for c in 0..3 {
            out[4 * r + c] = l[r][c] as f32;
        }
        out[4 * r + 3] = -(l[r][0] * t[0] + l[r][1] * t[1] + l[r][2] * t[2]) as f32;
    }
    Some(out)
}

/// Applies a row-major 3×4 transform to a point.
#[inline]
pub fn xform_point(m: &[f32; 12], p: [f32; 3]) -> [f32; 3] {
    [
        m[0] * p[0] + m[1] * p[1] + m[2] * p[2] + m[3],
        m[4] * p[0] + m[5] * p[1] + m[6] * p[2] + m[7],
        m[8] * p[0] + m[9] * p[1] + m[10] * p[2] + m[11],
    ]
}

/// Applies the linear part of a row-major 3×4 transform to a direction.
#[inline]
pub fn xform_vector(m: &[f32; 12], v: [f32; 3]) -> [f32; 3] {
    [
        m[0] * v[0] + m[1] * v[1] + m[2] * v[2],
        m[4] * v[0] + m[5] * v[1] + m[6] * v[2],
        m[8] * v[0] + m[9] * v[1] + m[10] * v[2],
    ]
}

/// All tables of a compiled hierarchy, borrowed (from a `CompiledScene` in memory or from a
/// mapped package), so the CPU oracle and the GPU uploader read one shape.
#[derive(Clone, Copy, Debug, Default)]
pub struct HierarchyView<'a> {
    pub root_tlas: u32,
    pub tlases: &'a [TlasRecord],
    pub instances: &'a [InstanceRecord],
    pub blases: &'a [BlasRecord],
    pub geometries: &'a [GeometryRecord],
    pub pis: &'a [PiRecord],
    pub lod_selectors: &'a [LodSelectorRecord],
    pub lod_levels: &'a [u32],
    pub meshes: &'a [MeshRecord],
    pub materials: &'a [MaterialRecord],
    /// Image textures (texels in [`HierarchyView::texels`]).
    pub textures: &'a [crate::shade::TextureRecord],
    /// RGBA8 texels of every texture's mip chain, one `u32` each (R in the low byte).
    pub texels: &'a [u32],
}

/// A broken reference in a hierarchy (from a corrupt package or a compiler bug).
#[derive(Debug, thiserror::Error)]
#[error("hierarchy: {table}[{index}]: {reason}")]
pub struct HierarchyError {
    pub table: &'static str,
    pub index: usize,
    pub reason: String,
}

impl HierarchyView<'_> {
    /// Whether `other` has this very instancing graph: the same root and the same TLAS,
    /// instance, BLAS and programmable-instance tables, by address and length (not equal
    /// copies). Data indexed by those tables (a package's stored stream split) applies only to
    /// a view that shares them.
    pub fn same_instancing(&self, other: &HierarchyView<'_>) -> bool {
        self.root_tlas == other.root_tlas
            && std::ptr::eq(self.tlases, other.tlases)
            && std::ptr::eq(self.instances, other.instances)
            && std::ptr::eq(self.blases, other.blases)
            && std::ptr::eq(self.pis, other.pis)
    }

    /// The TLASes and BLASes reachable from the root (through instances, programmable
    /// instances and LOD levels), as flags by index. Out-of-range references are skipped
    /// (`check_references` reports them).
    pub fn reachable(&self) -> (Vec<bool>, Vec<bool>) {
        let mut tlas = vec![false; self.tlases.len()];
        let mut blas = vec![false; self.blases.len()];
        let mut todo = Vec::new();
        let visit = |t: usize, tlas: &mut Vec<bool>, todo: &mut Vec<usize>| {
            if t < tlas.len() && !tlas[t] {
                tlas[t] = true;
                todo.push(t);
            }
        };
        visit(self.root_tlas as usize, &mut tlas, &mut todo);
        while let Some(t) = todo.pop() {
            let rec = &self.tlases[t];
            let range = rec.instance_range();
            for inst in self.instances.get(range).unwrap_or(&[]) {
                let b = inst.blas as usize;
                if b >= blas.len() || blas[b] {
                    continue;
                }
                blas[b] = true;
                let br = &self.blases[b];
                if br.kind != BLAS_AABBS {
                    continue;
                }
                let items = br.item_base as usize..(br.item_base as usize + br.item_count as usize);
                for pi in self.pis.get(items).unwrap_or(&[]) {
                    if pi.kind == PI_TLAS {
                        visit(pi.target as usize, &mut tlas, &mut todo);
                    } else if let Some(s) = self.lod_selectors.get(pi.target as usize) {
                        let levels =
                            s.level_base as usize..(s.level_base as usize + s.level_count as usize);
                        for &lt in self.lod_levels.get(levels).unwrap_or(&[]) {
                            visit(lt as usize, &mut tlas, &mut todo);
                        }
                    }
                }
            }
        }
        (tlas, blas)
    }

    /// Checks every cross-table reference is in range, so traversal can index without panics.
    pub fn check_references(&self) -> Result<(), HierarchyError> {
        self.check_references_then(&mut |_, _| {})
    }

    /// [`HierarchyView::check_references`] that calls `read(begin, end)` after instances
    /// `begin..end` were checked, every 2^15 (a caller whose table is a mapped file drops the
    /// pages read).
    pub fn check_references_then(
        &self,
        read: &mut dyn FnMut(usize, usize),
    ) -> Result<(), HierarchyError> {
        let err = |table, index, reason: String| {
            Err(HierarchyError {
                table,
                index,
                reason,
            })
        };
        let in_range =
            |base: u32, count: u32, len: usize| (base as u64 + count as u64) <= len as u64;
        if self.root_tlas as usize >= self.tlases.len() {
            return err(
                "root",
                0,
                format!("root TLAS {} of {}", self.root_tlas, self.tlases.len()),
            );
        }
        for (i, t) in self.tlases.iter().enumerate() {
            if !in_range(t.instance_base, t.instance_count, self.instances.len()) {
                return err("tlases", i, "instance range out of bounds".into());
            }
        }
        const PIECE: usize = 1 << 15;
        for (i, inst) in self.instances.iter().enumerate() {
            if i > 0 && i % PIECE == 0 {
                read(i - PIECE, i);
            }
            if inst.blas as usize >= self.blases.len() {
                return err("instances", i, format!("BLAS {} out of range", inst.blas));
            }
            if self.blases[inst.blas as usize].kind == BLAS_AABBS
                && inst.tlas_from_blas != IDENTITY_3X4
            {
                return err(
                    "instances",
                    i,
                    format!(
                        "AABB BLAS {} placed with a non-identity transform",
                        inst.blas
                    ),
                );
            }
        }
        read(self.instances.len() / PIECE * PIECE, self.instances.len());
        for (i, b) in self.blases.iter().enumerate() {
            let len = if b.kind == BLAS_TRIANGLES {
                self.geometries.len()
            } else if b.kind == BLAS_AABBS {
                self.pis.len()
            } else {
                return err("blases", i, format!("unknown kind {}", b.kind));
            };
            if !in_range(b.item_base, b.item_count, len) {
                return err("blases", i, "item range out of bounds".into());
            }
        }
        for (i, g) in self.geometries.iter().enumerate() {
            if g.mesh as usize >= self.meshes.len() {
                return err("geometries", i, format!("mesh {} out of range", g.mesh));
            }
        }
        for (i, p) in self.pis.iter().enumerate() {
            let ok = match p.kind {
                PI_TLAS => (p.target as usize) < self.tlases.len(),
                PI_LOD_SELECTOR => (p.target as usize) < self.lod_selectors.len(),
                _ => false,
            };
            if !ok {
                return err(
                    "pis",
                    i,
                    format!("kind {} target {} invalid", p.kind, p.target),
                );
            }
        }
        for (i, s) in self.lod_selectors.iter().enumerate() {
            if s.level_count == 0 || !in_range(s.level_base, s.level_count, self.lod_levels.len()) {
                return err("lod_selectors", i, "level range invalid".into());
            }
        }
        for (i, &t) in self.lod_levels.iter().enumerate() {
            if t as usize >= self.tlases.len() {
                return err("lod_levels", i, format!("TLAS {t} out of range"));
            }
        }
        for (i, m) in self.meshes.iter().enumerate() {
            if m.material as usize >= self.materials.len() {
                return err("meshes", i, format!("material {} out of range", m.material));
            }
        }
        for (i, t) in self.textures.iter().enumerate() {
            if t.texel_offset as u64 + t.texel_count() > self.texels.len() as u64 {
                return err("textures", i, "texel range out of bounds".into());
            }
        }
        for (i, m) in self.materials.iter().enumerate() {
            for t in [m.base_color_texture, m.alpha_texture] {
                if t != NONE_U32 && t as usize >= self.textures.len() {
                    return err("materials", i, format!("texture {t} out of range"));
                }
            }
        }
        Ok(())
    }
}

/// The TLAS and instance tables of a hierarchy whose root keeps only some elements' placements
/// (`motu render --subset`). Root-level placements carry their element, also where a split
/// moved them into the root's pieces; those of other elements are dropped and nothing below
/// them is ever reached. Other tables are borrowed unchanged.
#[derive(Clone, Debug)]
pub struct RootSubset {
    pub tlases: Vec<TlasRecord>,
    pub instances: Vec<InstanceRecord>,
    pub blases: Vec<BlasRecord>,
    pub pis: Vec<PiRecord>,
    pub root_tlas: u32,
    /// Tagged placements (root and split pieces) kept and dropped.
    pub kept: u32,
    pub dropped: u32,
}

impl RootSubset {
    /// Appends a filtered copy of the root TLAS (a new record and a new instance range), and
    /// re-points every other TLAS that holds a dropped placement (the pieces of a split root)
    /// at a filtered copy of its range (a piece may end up empty). Instances whose element is
    /// `NONE_U32` (shared, or below the root) are kept.
    pub fn new(
        view: &HierarchyView<'_>,
        keep_element: impl Fn(u32) -> bool,
    ) -> Result<Self, HierarchyError> {
        view.check_references()?;
        let too_many = |what: &str| HierarchyError {
            table: "subset",
            index: 0,
            reason: format!("too many {what}"),
        };
        let keep = |inst: &InstanceRecord| inst.element == NONE_U32 || keep_element(inst.element);
        let mut tlases = view.tlases.to_vec();
        let mut instances = view.instances.to_vec();
        let (mut kept, mut dropped) = (0u32, 0u32);
        let root = view.root_tlas as usize;
        let mut filtered = |rec: &TlasRecord,
                            instances: &mut Vec<InstanceRecord>|
         -> Result<Option<TlasRecord>, HierarchyError> {
            let range = rec.instance_range();
            let src = &view.instances[range];
            let tagged = src.iter().filter(|i| i.element != NONE_U32).count() as u32;
            let n_keep = src.iter().filter(|i| keep(i)).count();
            kept += tagged - (src.len() - n_keep) as u32;
            dropped += (src.len() - n_keep) as u32;
            if n_keep == src.len() {
                return Ok(None);
            }
            let base = u32::try_from(instances.len()).map_err(|_| too_many("instances"))?;
            instances.extend(src.iter().filter(|i| keep(i)));
            Ok(Some(TlasRecord {
                instance_base: base,
                instance_count: n_keep as u32,
                ..*rec
            }))
        };
        for (t, rec) in view.tlases.iter().enumerate() {
            if t != root {
                if let Some(new) = filtered(rec, &mut instances)? {
                    tlases[t] = new;
                }
            }
        }
        let root_rec = view.tlases[root];
        let base = instances.len();
        let new_root = match filtered(&root_rec, &mut instances)? {
            Some(new) => new,
            None => {
                let base = u32::try_from(base).map_err(|_| too_many("instances"))?;
                instances.extend_from_within(root_rec.instance_range());
                TlasRecord {
                    instance_base: base,
                    ..root_rec
                }
            }
        };
        tlases.push(new_root);
        let root_tlas = u32::try_from(tlases.len() - 1).map_err(|_| too_many("TLASes"))?;
        let (instances, blases, pis) = compact_reachable(view, root_tlas, &mut tlases, instances);
        Ok(Self {
            tlases,
            instances,
            blases,
            pis,
            root_tlas,
            kept,
            dropped,
        })
    }

    /// The hierarchy seen through the filtered root.
    pub fn view<'a>(&'a self, base: &HierarchyView<'a>) -> HierarchyView<'a> {
        HierarchyView {
            root_tlas: self.root_tlas,
            tlases: &self.tlases,
            instances: &self.instances,
            blases: &self.blases,
            pis: &self.pis,
            ..*base
        }
    }
}

/// Keeps only the instance and programmable-instance records the subset's root reaches: the
/// renderer uploads these tables whole, and at scale the other elements' records would cost
/// more than the subset's structures. TLAS and BLAS indices are unchanged (unreached ones keep
/// their record with an empty range), so nothing else is renumbered.
fn compact_reachable(
    base: &HierarchyView<'_>,
    root_tlas: u32,
    tlases: &mut [TlasRecord],
    instances: Vec<InstanceRecord>,
) -> (Vec<InstanceRecord>, Vec<BlasRecord>, Vec<PiRecord>) {
    let (reach_tlas, reach_blas) = HierarchyView {
        root_tlas,
        tlases,
        instances: &instances,
        ..*base
    }
    .reachable();
    let mut kept_instances = Vec::new();
    for (t, rec) in tlases.iter_mut().enumerate() {
        let range = rec.instance_range();
        if reach_tlas[t] {
            // Fits u32: a subsequence of `instances`, whose ranges are u32.
            rec.instance_base = kept_instances.len() as u32;
            kept_instances.extend_from_slice(&instances[range]);
        } else {
            rec.instance_base = 0;
            rec.instance_count = 0;
        }
    }
    let mut blases = base.blases.to_vec();
    let mut pis = Vec::new();
    for (b, rec) in blases.iter_mut().enumerate() {
        if rec.kind != BLAS_AABBS {
            continue;
        }
        let range = rec.item_base as usize..(rec.item_base + rec.item_count) as usize;
        if reach_blas[b] {
            rec.item_base = pis.len() as u32;
            pis.extend_from_slice(&base.pis[range]);
        } else {
            rec.item_base = 0;
            rec.item_count = 0;
        }
    }
    (kept_instances, blases, pis)
}

#[cfg(test)]
mod tests;
