//! Splitting a TLAS over an instance cap into spatial pieces (compile time, and at load time
//! for streaming: [`split_for_streaming`]).

use crate::instance_map::RELEASE_EVERY_RECORDS;
use crate::instance_table::ScratchArray;
use crate::split::{
    sah_partition_paged, split_keeping_direct_paged, Pages, Scratch, RELEASE_ITEMS,
};
use crate::tables::{instance_bounds, next_id, set_bounds};
use crate::InstanceTable;
use crate::{xform, CompileError, CompiledScene};
use motu_abi::{
    BlasRecord, HierarchyView, InstanceRecord, PiRecord, TlasRecord, BLAS_AABBS, NONE_U32, PI_TLAS,
};
use motu_scene::{Aabb, Transform34};

/// An instance's bounds, `(min, max)`.
type Bounds = ([f32; 3], [f32; 3]);
use std::path::Path;

mod order;
mod stash;

use order::for_each_released;
#[cfg(test)]
pub(crate) use order::rotate_to_tail;
use order::{gather_in_order, move_range_to_tail, tag_origins, untag_in_order};

/// Splits `tlas` until its instance count fits `cap` (see the crate docs): the few instances
/// large against the whole (terrain, ocean) stay in `tlas` itself, traced with it, and the
/// rest is cut by a binned SAH over instance bounds into compact leaves; the densest leaves
/// become pieces (barely overlapping, so a ray enters few of them and skips those behind its
/// hit) and the others stay in `tlas` too, up to the cap, so rays that only meet them take one
/// trace. Pieces mix elements; their instances keep their element tags, which `--subset`
/// filters on. `tlas`'s instance range must be the instance table's tail.
/// `new_aabb_blas(element)` is told of each AABB BLAS made (with the element its pieces share,
/// or `NONE_U32`); `root`: `tlas` is the root, whose instances carry elements.
/// `scratch`: a directory for [`stash`]: a TLAS of at least [`stash::MIN_INSTANCES`] is split
/// by key (its records wait in an unnamed file there while the partition moves indices).
pub(crate) fn split_tlas(
    out: &mut CompiledScene,
    tlas: u32,
    cap: usize,
    per_blas: usize,
    root: bool,
    scratch: Option<&Path>,
    new_aabb_blas: &mut dyn FnMut(u32),
) -> Result<(), CompileError> {
    let mut ranges: Vec<(usize, usize)> = Vec::new();
    let mut first_round = true;
    loop {
        let t = out.tlases[tlas as usize];
        let (base, count) = (t.instance_base as usize, t.instance_count as usize);
        if count <= cap {
            return Ok(());
        }
        let _span = tracing::debug_span!("split", tlas, instances = count).entered();
        // The range is the table's tail (just emitted, or the previous round's output), so
        // what stays direct can sit at its end and the new AABB instances follow it.
        debug_assert_eq!(base + count, out.instances.len());
        if first_round {
            out.report.split_tlases += 1;
        }
        // A large range is partitioned as indices (4 bytes, not a 64-byte record, beside its
        // bounds) while its records wait in a file, read back for their bounds: the table and
        // the partition's arrays are never resident together (issue 48 item 1: the import's
        // peak where a root is split). A mapped table's range goes from a smaller size: in
        // memory its records would all be resident while the partition moves them.
        let keyed_from = if out.instances.is_mapped() {
            crate::PARK_MIN_INSTANCES.min(stash::MIN_INSTANCES)
        } else {
            stash::MIN_INSTANCES
        };
        let mut stashed = match scratch {
            Some(dir) if count >= keyed_from => {
                Some(stash::Stash::take_tail(&mut out.instances, base, dir)?)
            }
            _ => None,
        };
        let blases = &out.blases;
        let bounds_of = |inst: &InstanceRecord| {
            let b = instance_bounds(blases, inst);
            (b.min, b.max)
        };
        ranges.clear();
        // A mapped table's keyed split keeps its bounds and indices in mapped files too (28
        // bytes an instance: 0.8 GB at scale 1's 28M), their pages released behind the
        // partition's passes; the first round permutes them through two more such files.
        let map_dir = match (&stashed, scratch) {
            (Some(_), Some(dir)) if out.instances.is_mapped() => Some(dir),
            _ => None,
        };
        let (direct, order, bounds) = if let Some(s) = stashed.as_mut() {
            let mut bounds = ScratchArray::<Bounds>::zeroed(count, map_dir)?;
            let mut order = ScratchArray::<u32>::zeroed(count, map_dir)?;
            // The bounds, the indices and the first round's scratch are all mapped, or none.
            let pages = bounds.pages();
            s.map_records_into(&mut bounds, pages, bounds_of)?;
            next_id(count, "instances")?;
            for (k, chunk) in order.chunks_mut(RELEASE_ITEMS).enumerate() {
                for (j, o) in chunk.iter_mut().enumerate() {
                    *o = (k * RELEASE_ITEMS + j) as u32;
                }
                pages.release(chunk);
            }
            let (mut s_order, mut s_bounds) = match (first_round, map_dir) {
                (true, Some(dir)) => (
                    Some(ScratchArray::<u32>::zeroed(count, Some(dir))?),
                    Some(ScratchArray::<Bounds>::zeroed(count, Some(dir))?),
                ),
                _ => (None, None),
            };
            let through = match (s_order.as_mut(), s_bounds.as_mut()) {
                (Some(o), Some(b)) => Some((&mut o[..], &mut b[..])),
                _ => None,
            };
            let direct = partition_round(
                &mut order,
                &mut bounds,
                first_round,
                cap,
                per_blas,
                &mut ranges,
                pages,
                through,
            );
            (direct, Some((order, pages)), bounds)
        } else {
            use rayon::prelude::*;
            let mut bounds: Vec<Bounds> = out.instances[base..].par_iter().map(bounds_of).collect();
            let direct = partition_round(
                &mut out.instances[base..],
                &mut bounds,
                first_round,
                cap,
                per_blas,
                &mut ranges,
                Pages::HEAP,
                None,
            );
            (direct, None, ScratchArray::from_vec(bounds))
        };
        first_round = false;
        let pages = order.as_ref().map_or(Pages::HEAP, |o| o.1);
        // The instances' bounds were permuted with them: a piece's are its range's.
        let piece_bounds: Vec<Aabb> = ranges
            .iter()
            .map(|&(x, y)| {
                let mut acc = Aabb::EMPTY;
                for (k, &(min, max)) in bounds[x..y].iter().enumerate() {
                    acc = acc.union(&Aabb { min, max });
                    if (k + 1) % RELEASE_ITEMS == 0 {
                        pages.release(&bounds[x + k + 1 - RELEASE_ITEMS..x + k + 1]);
                    }
                }
                pages.release(&bounds[x..y]);
                acc
            })
            .collect();
        drop(bounds);
        if let (Some(s), Some((order, pages))) = (stashed, order) {
            s.put_back(&mut out.instances, &order, pages)?;
        }
        let split_end = base + count - direct;
        let first_piece = out.tlases.len();
        for (&(x, y), piece_bounds) in ranges.iter().zip(&piece_bounds) {
            let (x, y) = (base + x, base + y);
            next_id(out.tlases.len(), "TLASes")?;
            let mut rec = TlasRecord {
                instance_base: x as u32,
                instance_count: (y - x) as u32,
                element: match common_element_released(&out.instances, x, y) {
                    Some(e) if e != NONE_U32 => e,
                    _ => t.element,
                },
                ..Default::default()
            };
            set_bounds(&mut rec.bounds_min, &mut rec.bounds_max, piece_bounds);
            out.tlases.push(rec);
        }
        let piece_end = out.tlases.len();
        out.report.split_pieces += (piece_end - first_piece) as u64;
        // PIs to the pieces (in spatial order), grouped into AABB BLASes; the TLAS now
        // instances those, after the instances it keeps.
        let mut piece = first_piece;
        while piece < piece_end {
            let group_end = (piece + per_blas).min(piece_end);
            let pi_begin = out.pis.len();
            for target in piece..group_end {
                let pt = &out.tlases[target];
                let pi = PiRecord {
                    child_from_parent: xform::to_array(&Transform34::IDENTITY),
                    aabb_min: pt.bounds_min,
                    kind: PI_TLAS,
                    aabb_max: pt.bounds_max,
                    target: target as u32,
                };
                next_id(out.pis.len(), "programmable instances")?;
                out.pis.push(pi);
            }
            let blas = push_aabb_blas(out, pi_begin, out.pis.len())?;
            let element = common_element(out.tlases[piece..group_end].iter().map(|t| t.element))
                .unwrap_or(NONE_U32);
            new_aabb_blas(element);
            // Root instances carry their element (`--subset`); below the root the parent
            // decides.
            next_id(out.instances.len(), "instances")?;
            out.instances.push(InstanceRecord {
                tlas_from_blas: xform::to_array(&Transform34::IDENTITY),
                blas,
                flags: 0,
                element: if root { element } else { NONE_U32 },
                _pad: 0,
            })?;
            piece = group_end;
        }
        let t = &mut out.tlases[tlas as usize];
        t.instance_base = next_id(split_end, "instances")?;
        t.instance_count = next_id(out.instances.len() - split_end, "instances")?;
    }
}

/// One round of [`split_tlas`] over `items` (records, or their indices) and their bounds,
/// permuted together: the first keeps the large instances and the sparse part direct
/// (returns how many stay, at the range's end), later rounds cut everything into pieces.
#[allow(clippy::too_many_arguments)]
fn partition_round<T: Copy + Send + bytemuck::Zeroable>(
    items: &mut [T],
    bounds: &mut [Bounds],
    first_round: bool,
    cap: usize,
    per_blas: usize,
    ranges: &mut Vec<(usize, usize)>,
    pages: Pages,
    scratch: Option<Scratch<'_, T>>,
) -> usize {
    if !first_round {
        sah_partition_paged(items, bounds, cap, ranges, pages);
        return 0;
    }
    let count = items.len();
    let large = keep_large_at_end(items, bounds, cap, pages);
    // Beside the large ones, the TLAS keeps as many instances as the cap leaves room for
    // next to its pieces' AABB instances: rays into that part take one trace, and only the
    // densest clusters become pieces.
    let rest = count - large;
    let scratch = scratch.map(|(i, b)| (&mut i[..rest], &mut b[..rest]));
    let kept = split_keeping_direct_paged(
        &mut items[..rest],
        &mut bounds[..rest],
        cap,
        |pieces| cap.saturating_sub(large + pieces.div_ceil(per_blas.max(1))),
        ranges,
        pages,
        scratch,
    );
    large + kept
}

/// Appends an AABB BLAS over PIs `begin..end` (bounds from their boxes) and returns its id.
pub(crate) fn push_aabb_blas(
    out: &mut CompiledScene,
    begin: usize,
    end: usize,
) -> Result<u32, CompileError> {
    let id = next_id(out.blases.len(), "BLASes")?;
    let bounds = out.pis[begin..end].iter().fold(Aabb::EMPTY, |b, pi| {
        b.union(&xform::aabb_from_record(pi.aabb_min, pi.aabb_max))
    });
    let count = next_id(end - begin, "PIs in one BLAS")?;
    let mut rec = BlasRecord {
        kind: BLAS_AABBS,
        item_base: next_id(begin, "programmable instances")?,
        item_count: count,
        primitive_count: count,
        ..Default::default()
    };
    set_bounds(&mut rec.bounds_min, &mut rec.bounds_max, &bounds);
    out.blases.push(rec);
    Ok(id)
}

/// [`common_element`] of records `x..y` of `table`, read a piece at a time (a mapped table's
/// pages dropped behind).
fn common_element_released(table: &InstanceTable, x: usize, y: usize) -> Option<u32> {
    let first = table.get(x)?.element;
    let mut at = x;
    while at < y {
        let end = (at + RELEASE_EVERY_RECORDS).min(y);
        let same = table[at..end].iter().all(|i| i.element == first);
        table.release_range(at, end);
        if !same {
            return None;
        }
        at = end;
    }
    Some(first)
}

/// The one element all of `elements` carry (`NONE_U32` ones included as such), if any.
fn common_element(mut elements: impl Iterator<Item = u32>) -> Option<u32> {
    let first = elements.next()?;
    elements.all(|e| e == first).then_some(first)
}

/// Moves the instances whose bounds are large against the whole range (terrain, ocean: in
/// any piece they would make its box span the scene) to the end of `instances` (`bounds`
/// alongside) and returns how many: those with a surface area of at least the whole's over
/// the piece count, the largest first, at most a quarter of `cap`, so the parent keeps room
/// for the pieces' AABB instances.
fn keep_large_at_end<T: bytemuck::Zeroable>(
    instances: &mut [T],
    bounds: &mut [Bounds],
    cap: usize,
    pages: Pages,
) -> usize {
    let n = instances.len();
    let area = |b: &Bounds| Aabb { min: b.0, max: b.1 }.surface_area();
    let mut whole = Aabb::EMPTY;
    for (i, b) in bounds.iter().enumerate() {
        whole = whole.union(&Aabb { min: b.0, max: b.1 });
        if (i + 1) % RELEASE_ITEMS == 0 {
            pages.release(&bounds[i + 1 - RELEASE_ITEMS..i + 1]);
        }
    }
    pages.release(bounds);
    let pieces = n.div_ceil(cap.max(1)).max(2);
    let threshold = whole.surface_area() / pieces as f32;
    if !(threshold.is_finite() && threshold > 0.0) {
        return 0;
    }
    let mut large: Vec<(f32, usize)> = Vec::new();
    for (i, b) in bounds.iter().enumerate() {
        let a = area(b);
        if a >= threshold {
            large.push((a, i));
        }
        if (i + 1) % RELEASE_ITEMS == 0 {
            pages.release(&bounds[i + 1 - RELEASE_ITEMS..i + 1]);
        }
    }
    pages.release(bounds);
    large.sort_unstable_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    large.truncate(cap / 4);
    let mut picked: Vec<usize> = large.into_iter().map(|(_, i)| i).collect();
    // Swap the picked to the tail, highest index first so none is moved before it is taken.
    picked.sort_unstable_by(|a, b| b.cmp(a));
    for (k, &i) in picked.iter().enumerate() {
        let dst = n - 1 - k;
        instances.swap(i, dst);
        bounds.swap(i, dst);
    }
    picked.len()
}

/// The instance cap above which a streamer splits a TLAS into pieces when it loads a package
/// ([`split_for_streaming`]). A streamed TLAS is rebuilt whenever the residency of a BLAS it
/// instances changes, and pieces are rebuilt one at a time, so this bounds the room a rebuild
/// takes from resident BLASes. Measured on island 0.3 at a quarter of its full build (H200):
/// 1M-instance pieces 2.64 passes a frame after the first, 256k pieces 2.91, unsplit 3.00
/// (BENCHMARKS.md, session 21).
pub const STREAM_SPLIT_INSTANCES: u32 = 1_000_000;

/// A compiled hierarchy with its large TLASes split for streaming (owned tables; the texels
/// stay with the view it was made from).
#[derive(Debug)]
pub struct StreamSplit {
    scene: CompiledScene,
    /// The instance table moved off the heap ([`StreamSplit::park_instances`]); `scene`'s is
    /// empty then.
    parked: Option<crate::instance_map::InstanceMap>,
}

impl StreamSplit {
    /// The split hierarchy's view; `base` is the view it was made from (its textures and
    /// texels: a split never changes them).
    pub fn view<'a>(&'a self, base: &HierarchyView<'a>) -> HierarchyView<'a> {
        HierarchyView {
            textures: base.textures,
            texels: base.texels,
            instances: self.instances(),
            ..self.scene.view()
        }
    }

    /// The split's instance table, on the heap or parked.
    fn instances(&self) -> &[InstanceRecord] {
        match &self.parked {
            Some(m) => m.records(),
            None => &self.scene.instances[..],
        }
    }

    /// Moves the split's instance table (of at least [`crate::PARK_MIN_INSTANCES`] records;
    /// smaller tables stay) into an unnamed file in `dir`, mapped read-only (a table already
    /// in a mapped file, [`InstanceTable::in_file`], stops writing: no copy):
    /// [`StreamSplit::view`] reads the map and [`StreamSplit::release_instance_pages`] drops
    /// what was read from the resident set, so an import holds no instance table while it
    /// makes the proxy clusters (issue 48 item 1). Returns whether it parked the table; on an
    /// error a heap table stays on the heap (a mapped one is lost: the caller fails).
    pub fn park_instances(&mut self, dir: &Path) -> Result<bool, CompileError> {
        if self.parked.is_some()
            || self.scene.instances.len() < crate::instance_map::PARK_MIN_INSTANCES
        {
            return Ok(false);
        }
        let map = match std::mem::take(&mut self.scene.instances).into_map() {
            Ok(map) => map?,
            Err(heap) => {
                let map = crate::instance_map::InstanceMap::write(&heap, dir);
                self.scene.instances = heap;
                let map = map.map_err(|source| CompileError::Scratch {
                    dir: dir.to_path_buf(),
                    source,
                })?;
                self.scene.instances = InstanceTable::new();
                map
            }
        };
        self.parked = Some(map);
        Ok(true)
    }

    /// Drops a parked table's pages from the resident set (they fault back in, unchanged,
    /// when read again; a no-op on the heap). A failed hint costs only memory: logged.
    pub fn release_instance_pages(&self) {
        if let Some(m) = &self.parked {
            if let Err(error) = m.release_pages() {
                tracing::debug!(%error, "could not release the parked instances' pages");
            }
        }
    }

    /// Puts the instance table [`stream_split_taking_instances`] took back into `compiled`, in
    /// its order (`stored`: the split's map, which that call returned with `self`).
    pub fn give_back(
        self,
        compiled: &mut CompiledScene,
        stored: &StoredStreamSplit,
    ) -> Result<(), CompileError> {
        let source = &stored.instance_source;
        let len = self.instances().len();
        if len != source.len() || stored.extra_instances.len() > source.len() {
            return Err(CompileError::Internal(format!(
                "the stream split's map names {} instances ({} extra) for {len}",
                source.len(),
                stored.extra_instances.len(),
            )));
        }
        let n = source.len() - stored.extra_instances.len();
        if let Some(map) = &self.parked {
            compiled.instances = gather_in_order(map, source, n)?.into();
            return Ok(());
        }
        let mut instances = self.scene.instances.into_vec();
        for (r, &s) in instances.iter_mut().zip(source) {
            r._pad = if s == NONE_U32 { 0 } else { s + 1 };
        }
        compiled.instances = untag_in_order(instances, n)?.into();
        Ok(())
    }

    /// TLASes split, and pieces made.
    pub fn counts(&self) -> (u64, u64) {
        let r = &self.scene.report;
        (r.split_tlases, r.split_pieces)
    }

    /// The split in the form a package stores it ([`StoredStreamSplit`]), made from a
    /// hierarchy of `n` instances; `self` must come from [`split_tagged`] (origins in `_pad`).
    fn stored(&self, n: usize) -> StoredStreamSplit {
        let (tlases_split, pieces) = self.counts();
        let mut source = Vec::with_capacity(self.instances().len());
        let mut extra_instances = Vec::new();
        for (i, inst) in self.instances().iter().enumerate() {
            if i > 0 && i % RELEASE_EVERY_RECORDS == 0 {
                self.release_instance_range(i - RELEASE_EVERY_RECORDS, i);
            }
            // `split_for_streaming` tags each copied instance with its index + 1 (in `_pad`);
            // the split's own AABB-BLAS instances carry 0.
            if inst._pad != 0 && (inst._pad as usize) <= n {
                source.push(inst._pad - 1);
            } else {
                source.push(NONE_U32);
                extra_instances.push(InstanceRecord { _pad: 0, ..*inst });
            }
        }
        StoredStreamSplit {
            tlases_split,
            pieces,
            tlases: self.scene.tlases.clone(),
            blases: self.scene.blases.clone(),
            pis: self.scene.pis.clone(),
            instance_source: source,
            extra_instances,
        }
    }

    /// Drops the pages of records `begin..end` of a mapped table (the split's own or a parked
    /// one) from the resident set.
    fn release_instance_range(&self, begin: usize, end: usize) {
        match &self.parked {
            Some(m) => {
                let _ = m.release_range(begin, end);
            }
            None => self.scene.instances.release_range(begin, end),
        }
    }

    /// The split a package stored ([`StreamSplit::stored`]), rebuilt over `view` (the
    /// package's hierarchy) without splitting anything: O(instances). Checks that the stored
    /// tables fit `view` (every source index in range, as many extra instances as named,
    /// every cross-table reference valid), so a damaged package is an error, not a panic.
    pub fn from_stored(
        view: &HierarchyView<'_>,
        stored: &StoredStreamSplit,
    ) -> Result<StreamSplit, CompileError> {
        let bad = |what: String| CompileError::Internal(format!("stored stream split: {what}"));
        let instances = gather_stored_instances(view, stored).map_err(bad)?;
        let scene = CompiledScene {
            root_tlas: view.root_tlas,
            tlases: stored.tlases.clone(),
            instances: instances.into(),
            blases: stored.blases.clone(),
            geometries: view.geometries.to_vec(),
            pis: stored.pis.clone(),
            lod_selectors: view.lod_selectors.to_vec(),
            lod_levels: view.lod_levels.to_vec(),
            meshes: view.meshes.to_vec(),
            materials: view.materials.to_vec(),
            textures: view.textures.to_vec(),
            texels: Vec::new(),
            report: crate::CompileReport {
                split_tlases: stored.tlases_split,
                split_pieces: stored.pieces,
                ..Default::default()
            },
        };
        scene
            .view()
            .check_references()
            .map_err(CompileError::StoredSplit)?;
        Ok(StreamSplit {
            scene,
            parked: None,
        })
    }
}

/// The split's instance table from a stored map (see [`StoredStreamSplit`]): a gather of
/// millions of records, in parallel pieces, each knowing from a first pass how many extra
/// instances the pieces before it take. The first problem in map order is the error.
fn gather_stored_instances(
    view: &HierarchyView<'_>,
    stored: &StoredStreamSplit,
) -> Result<Vec<InstanceRecord>, String> {
    use rayon::prelude::*;
    const PIECE: usize = 1 << 16;
    let source = &stored.instance_source;
    let extra = &stored.extra_instances;
    let nones: Vec<usize> = source
        .par_chunks(PIECE)
        .map(|c| c.iter().filter(|&&s| s == NONE_U32).count())
        .collect();
    let mut first_extra = Vec::with_capacity(nones.len());
    let mut total = 0usize;
    for n in &nones {
        first_extra.push(total);
        total += n;
    }
    if let Some(&s) = source
        .par_iter()
        .find_first(|&&s| s != NONE_U32 && s as usize >= view.instances.len())
    {
        return Err(format!("instance {s} is out of range"));
    }
    match total.cmp(&extra.len()) {
        std::cmp::Ordering::Greater => {
            return Err("fewer extra instances than the map names".into())
        }
        std::cmp::Ordering::Less => return Err("more extra instances than the map names".into()),
        std::cmp::Ordering::Equal => {}
    }
    let mut instances = vec![InstanceRecord::default(); source.len()];
    instances
        .par_chunks_mut(PIECE)
        .zip(source.par_chunks(PIECE))
        .zip(first_extra.par_iter())
        .for_each(|((out, map), &first)| {
            let mut e = first;
            for (o, &s) in out.iter_mut().zip(map) {
                *o = if s == NONE_U32 {
                    e += 1;
                    extra[e - 1]
                } else {
                    view.instances[s as usize]
                };
            }
        });
    Ok(instances)
}

/// A [`StreamSplit`] as a package stores it, so that readers (`motu report`) need not split
/// again: the split hierarchy's TLAS, BLAS and PI tables whole (they are small: the split adds
/// a few pieces, PIs and AABB BLASes), and its instance table as a map into the package's
/// (`instance_source[i]`: the package instance the split's instance `i` is, or `NONE_U32` for
/// the next of `extra_instances`, the split's own AABB-BLAS instances). Every other table is
/// the package's own.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StoredStreamSplit {
    pub tlases_split: u64,
    pub pieces: u64,
    pub tlases: Vec<TlasRecord>,
    pub blases: Vec<BlasRecord>,
    pub pis: Vec<PiRecord>,
    pub instance_source: Vec<u32>,
    pub extra_instances: Vec<InstanceRecord>,
}

/// Splits every TLAS of `view` over `cap` instances into spatial pieces, as `import
/// --max-instances cap` would have (the same split: large instances kept in the parent, the
/// densest clusters made pieces under PIs), at load time: a package keeps one unsplit root for
/// full builds, which trace it faster (a split root costs a 1080p frame of island 0.3 11–20% on
/// the H200, 1.69 traces a ray), and a streamer rebuilds the pieces one at a time. Instance
/// order changes inside a split TLAS; hit records name meshes and primitives, so images and
/// AOVs do not. `None` when no TLAS is over `cap`.
pub fn split_for_streaming(
    view: &HierarchyView<'_>,
    cap: u32,
) -> Result<Option<StreamSplit>, CompileError> {
    let mut split = split_tagged(view, cap)?;
    if let Some(s) = split.as_mut() {
        clear_origins(s);
    }
    Ok(split)
}

/// [`split_for_streaming`] in the form a package stores it (`motu import` writes it, `motu
/// report` reads it back with [`StreamSplit::from_stored`]). `None` when no TLAS is over `cap`.
pub fn stored_stream_split(
    view: &HierarchyView<'_>,
    cap: u32,
) -> Result<Option<StoredStreamSplit>, CompileError> {
    Ok(split_tagged(view, cap)?.map(|s| s.stored(view.instances.len())))
}

/// [`stored_stream_split`] of `compiled` itself, without a copy of its instance table (the
/// import's largest table: 64 bytes an instance): the table is moved into the split, tagged,
/// and put back in its order afterwards. `compiled` is unchanged on success; on an error its
/// instance table may be lost (the caller fails the import).
pub fn stored_stream_split_in_place(
    compiled: &mut CompiledScene,
    cap: u32,
) -> Result<Option<StoredStreamSplit>, CompileError> {
    let Some((stored, split)) = stream_split_taking_instances(compiled, cap)? else {
        return Ok(None);
    };
    split.give_back(compiled, &stored)?;
    Ok(Some(stored))
}

/// [`stored_stream_split_in_place`] that keeps the split for the caller: `compiled`'s instance
/// table is moved into the split, in the split's order and with the records a reader's
/// [`StreamSplit::from_stored`] rebuilds, and `compiled.instances` stays empty until
/// [`StreamSplit::give_back`] puts the table back in its order. The import makes the proxy
/// boxes and clusters over the split this way, without a second instance table beside the
/// package's (64 bytes an instance at its peak).
pub fn stream_split_taking_instances(
    compiled: &mut CompiledScene,
    cap: u32,
) -> Result<Option<(StoredStreamSplit, StreamSplit)>, CompileError> {
    stream_split_taking_instances_in(compiled, cap, None)
}

/// [`stream_split_taking_instances`] whose large TLASes are split by key, their records
/// waiting in an unnamed file in `scratch` meanwhile (the same split: see `stash`).
pub fn stream_split_taking_instances_in(
    compiled: &mut CompiledScene,
    cap: u32,
    scratch: Option<&Path>,
) -> Result<Option<(StoredStreamSplit, StreamSplit)>, CompileError> {
    let Some(over) = over_cap(&compiled.tlases, cap) else {
        return Ok(None);
    };
    let n = compiled.instances.len();
    let mut instances = std::mem::take(&mut compiled.instances);
    tag_origins(&mut instances)?;
    let view = compiled.view();
    let mut out = CompiledScene {
        instances,
        ..tables_of(&view)
    };
    split_tagged_scene(&mut out, over, cap, scratch)?;
    let mut split = StreamSplit {
        scene: out,
        parked: None,
    };
    let stored = split.stored(n);
    split.release_instance_range(0, split.instances().len());
    // The origins are in `stored`; the records become the reader's (`_pad` 0, as in a package).
    for_each_released(&mut split.scene.instances, |_, r| r._pad = 0);
    Ok(Some((stored, split)))
}

/// The TLASes of over `cap` instances (`None`: none is).
fn over_cap(tlases: &[TlasRecord], cap: u32) -> Option<Vec<u32>> {
    let cap = cap.max(2) as usize;
    let over: Vec<u32> = (0..tlases.len() as u32)
        .filter(|&t| tlases[t as usize].instance_count as usize > cap)
        .collect();
    (!over.is_empty()).then_some(over)
}

/// Every table of `view` but the instances (left empty), copied.
fn tables_of(view: &HierarchyView<'_>) -> CompiledScene {
    CompiledScene {
        root_tlas: view.root_tlas,
        tlases: view.tlases.to_vec(),
        instances: InstanceTable::new(),
        blases: view.blases.to_vec(),
        geometries: view.geometries.to_vec(),
        pis: view.pis.to_vec(),
        lod_selectors: view.lod_selectors.to_vec(),
        lod_levels: view.lod_levels.to_vec(),
        meshes: view.meshes.to_vec(),
        materials: view.materials.to_vec(),
        textures: view.textures.to_vec(),
        texels: Vec::new(),
        report: Default::default(),
    }
}

/// [`split_for_streaming`] with each instance's origin left in `_pad` (index + 1; 0 for the
/// split's own AABB-BLAS instances).
fn split_tagged(view: &HierarchyView<'_>, cap: u32) -> Result<Option<StreamSplit>, CompileError> {
    let Some(over) = over_cap(view.tlases, cap) else {
        return Ok(None);
    };
    let mut instances: InstanceTable = view.instances.to_vec().into();
    tag_origins(&mut instances)?;
    let mut out = CompiledScene {
        instances,
        ..tables_of(view)
    };
    split_tagged_scene(&mut out, over, cap, None)?;
    Ok(Some(StreamSplit {
        scene: out,
        parked: None,
    }))
}

/// Splits the TLASes `over` of `out` (instances tagged with their origins) over `cap`.
fn split_tagged_scene(
    out: &mut CompiledScene,
    over: Vec<u32>,
    cap: u32,
    scratch: Option<&Path>,
) -> Result<(), CompileError> {
    let cap = cap.max(2) as usize;
    let _span = tracing::info_span!("split for streaming", tlases = over.len()).entered();
    crate::check_references(out).map_err(CompileError::References)?;
    let per_blas = crate::CompileOptions::default().max_primitives_per_blas as usize;
    for t in over {
        move_range_to_tail(out, t, scratch)?;
        let root = t == out.root_tlas;
        split_tlas(out, t, cap, per_blas, root, scratch, &mut |_| {})?;
    }
    // Levels (two more under each split TLAS) and bounds (the pieces', their PIs').
    crate::finalize::finalize(out)
}

/// Clears the origins [`split_tagged`] left in the instances' `_pad` (0 in every package).
fn clear_origins(split: &mut StreamSplit) {
    for_each_released(&mut split.scene.instances, |_, inst| inst._pad = 0);
}
