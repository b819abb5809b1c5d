//! The report's build, one method per phase of [`ReportBuild`] (as `motu-gpu`'s `stream/`
//! does for its long procedures): the graph, who owns what, flattening per element, the
//! element rows, the variants, the streaming rows and floor, the budget plan. Each phase adds
//! its wall time to `timings_ms` under the same name, in the same order, as before the split.

use std::collections::{BTreeMap, HashMap};

use motu_abi::{HierarchyView, InstanceRecord, PiRecord, NONE_U32};
use motu_compile::blas_counts::BlasCounts;

use super::{Report, ReportInput, Stored};
use crate::budget::{plan_budget, SubsetCoster};
use crate::cost::{blas_cost_of, tlas_cost, Cost, Expansion, Graph, Node};
use crate::owner::{Ownership, SHARED};
use crate::rows::{ElementReport, VariantReport};
use crate::sizes::{BlasShape, SizeSource};
use crate::streaming::{streaming_report, FloorAdapter, StreamSplitReport, StreamingReport};
use crate::timing::{PhaseTimings, Provenance, ReportSources};
use crate::ReportError;

/// Builds the report from `view` with what the package stored (see [`Stored`]).
pub(super) fn build(
    view: &HierarchyView<'_>,
    input: &ReportInput,
    sizes: &dyn SizeSource,
    budget_bytes: Option<u64>,
    stored: Stored<'_>,
) -> Result<Report, ReportError> {
    let _span = tracing::info_span!("report", package = %input.package).entered();
    let Stored {
        split: stored_split,
        clusters: stored_clusters,
        counts: stored_counts,
        cap: stored_cap,
        timings,
        references_checked,
    } = stored;
    let mut b = ReportBuild {
        view,
        input,
        sizes,
        timings,
        sources: ReportSources::default(),
        warnings: Vec::new(),
    };
    let g = b.graph(stored_counts, references_checked)?;
    let owners = b.ownership(&g);
    let flat = b.flatten_elements(&g, &owners)?;
    let coster = b.coster(&owners);
    let elements = b.element_rows(&g, &owners, &flat, &coster)?;
    let variants = b.variants(&g, &flat, &elements)?;
    let name_of = |l: u32| owners.name_of(input, l);
    let mut streaming = b.timings.time("streaming_rows", || {
        streaming_report(
            &g,
            &owners.own,
            &elements,
            &variants[0].cost,
            &flat.root_cost,
            &name_of,
        )
    });
    b.streaming_floor(&mut streaming, stored_split, stored_clusters, stored_cap)?;
    let t_budget = std::time::Instant::now();
    let budget = budget_bytes
        .map(|bytes| {
            plan_budget(
                bytes,
                &coster,
                &elements,
                &variants,
                sizes,
                &name_of,
                streaming.min_resident_bytes,
            )
        })
        .transpose()?;
    b.timings
        .add("budget", t_budget.elapsed().as_secs_f64() * 1e3);
    Ok(b.finish(&flat, elements, variants, budget, streaming))
}

/// The build's context: its inputs and what every phase adds to (timings, sources, warnings).
struct ReportBuild<'a, 'v> {
    view: &'a HierarchyView<'v>,
    input: &'a ReportInput,
    sizes: &'a dyn SizeSource,
    timings: PhaseTimings,
    sources: ReportSources,
    warnings: Vec<String>,
}

/// Who owns what (phase `ownership`): the root's placements by element label, each node's
/// owner, and the costs per label and per shared element set.
struct Owners {
    /// The root's placements (element label, BLAS, root instances placing it).
    labelled: Vec<Placement>,
    own: Ownership,
    /// The root is split into pieces (its skeleton is needed by every subset).
    split_root: bool,
    /// Labels present, in id order (named elements with no instances still get a row).
    labels: Vec<u32>,
    /// The label of untagged root instances.
    untagged: u32,
    owned: BTreeMap<u32, Cost>,
    unique_tris: HashMap<u32, u64>,
    mesh_counts: HashMap<u32, u64>,
    root_count: BTreeMap<u32, u64>,
    /// Shared costs by element set, sorted by set.
    group_list: Vec<(Vec<u32>, Cost)>,
    global: Cost,
}

impl Owners {
    /// Label `l`'s row name.
    fn name_of(&self, input: &ReportInput, l: u32) -> String {
        if l == self.untagged {
            "(untagged)".into()
        } else {
            input
                .element_names
                .get(l as usize)
                .cloned()
                .unwrap_or_else(|| format!("element#{l}"))
        }
    }
}

/// Phase `flatten_elements`: the single-level flattening per label, and the root TLAS as
/// compiled with what its element shares are divided by.
struct Flattened {
    flat: BTreeMap<u32, Expansion>,
    root_cost: Cost,
    root_pieces: u64,
    /// Root placements (a split root's pieces' instances included), at least 1.
    root_total: u64,
}

impl<'a, 'v> ReportBuild<'a, 'v> {
    /// The node graph with its BLAS counts (stored, else counted: phase `blas_counts`).
    fn graph(
        &mut self,
        stored_counts: Option<BlasCounts>,
        references_checked: bool,
    ) -> Result<Graph<'v>, ReportError> {
        self.sources.blas_counts = if stored_counts.is_some() {
            "package"
        } else {
            "computed"
        }
        .into();
        let view = self.view;
        let counts = match stored_counts {
            Some(c) => c,
            None => self.timings.time("blas_counts", || BlasCounts::of(view)),
        };
        self.timings.time("graph", || {
            Graph::new(*view, self.sizes, counts, references_checked)
        })
    }

    /// Who owns each node, and the costs per label and shared set (phase `ownership`).
    fn ownership(&mut self, g: &Graph<'_>) -> Owners {
        let t_own = std::time::Instant::now();
        let untagged = untagged_label(self.input, self.view);
        let (labelled, split_nodes) = root_placements(self.view, &g.counts, untagged);
        let root_blases: Vec<(u32, u32)> = labelled.iter().map(|&(l, b, _)| (l, b)).collect();
        let mut own = Ownership::compute(g, &root_blases);
        // A split root's skeleton (the PI BLASes into its pieces, the piece TLASes) is needed
        // by every subset, like untagged root instances.
        let split_root = !split_nodes.is_empty();
        for n in split_nodes {
            own.claim(n, untagged);
        }
        let names = self.input.element_names.len();
        let mut labels: Vec<u32> = (0..names as u32).collect();
        for &(l, _, _) in &labelled {
            if !labels.contains(&l) {
                labels.push(l);
            }
        }
        if split_root && !labels.contains(&untagged) {
            labels.push(untagged);
        }
        labels.sort_unstable();
        if labels.iter().any(|&l| l != untagged && l as usize >= names) {
            self.warnings
                .push("root instances name element ids the package's meta does not list".into());
        }

        // Owned costs per label and shared groups by element set.
        let mut owned: BTreeMap<u32, Cost> = labels.iter().map(|&l| (l, Cost::default())).collect();
        let mut unique_tris: HashMap<u32, u64> = HashMap::new();
        let mut mesh_counts: HashMap<u32, u64> = HashMap::new();
        let mut groups: HashMap<Vec<u32>, Cost> = HashMap::new();
        for (n, o) in own.iter() {
            let c = g.cost(n);
            if o == SHARED {
                if let Some(set) = own.shared_sets.get(&n) {
                    groups.entry(set.clone()).or_default().add(c);
                }
            } else {
                owned.entry(o).or_default().add(c);
                if let Node::Blas(_) = n {
                    *unique_tris.entry(o).or_default() += c.blas_triangles;
                }
                if let Node::Mesh(_) = n {
                    *mesh_counts.entry(o).or_default() += 1;
                }
            }
        }
        // Root instance records belong to their element.
        let mut root_count: BTreeMap<u32, u64> = BTreeMap::new();
        for &(l, _, n) in &labelled {
            *root_count.entry(l).or_default() += n;
            let c = owned.entry(l).or_default();
            c.table_bytes += std::mem::size_of::<InstanceRecord>() as u64 * n;
            c.seal();
        }
        let mut group_list: Vec<(Vec<u32>, Cost)> = groups.into_iter().collect();
        group_list.sort_by(|a, b| a.0.cmp(&b.0));
        let global = g.global_tables();
        self.timings
            .add("ownership", t_own.elapsed().as_secs_f64() * 1e3);
        Owners {
            labelled,
            own,
            split_root,
            labels,
            untagged,
            owned,
            unique_tris,
            mesh_counts,
            root_count,
            group_list,
            global,
        }
    }

    /// Flattening per element (single level) and the root TLAS as compiled (phase
    /// `flatten_elements`).
    fn flatten_elements(&mut self, g: &Graph<'_>, o: &Owners) -> Result<Flattened, ReportError> {
        let t_flat = std::time::Instant::now();
        let expanded_sl = g.expansions(1);
        let mut flat: BTreeMap<u32, Expansion> = BTreeMap::new();
        for &(l, b, n) in &o.labelled {
            let e = g.expand(std::iter::once((b, n)), 1, &expanded_sl);
            let f = flat.entry(l).or_default();
            f.tri_instances = f.tri_instances.saturating_add(e.tri_instances);
            f.instanced_triangles = f.instanced_triangles.saturating_add(e.instanced_triangles);
        }
        // The root TLAS as compiled, its share per element by root instance count.
        let root_rec = self.view.tlases[self.view.root_tlas as usize];
        let (mut root_cost, root_pieces) =
            tlas_cost(self.sizes, u64::from(root_rec.instance_count))?;
        root_cost.table_bytes += std::mem::size_of::<motu_abi::TlasRecord>() as u64;
        // Instance buffer and count are attributed to elements with their instance records.
        root_cost.instance_buffer_bytes = 0;
        root_cost.instances = 0;
        root_cost.seal();
        // Shared by root placements (a split root's pieces' instances included).
        let root_total = o.labelled.iter().map(|p| p.2).sum::<u64>().max(1);
        self.timings
            .add("flatten_elements", t_flat.elapsed().as_secs_f64() * 1e3);
        Ok(Flattened {
            flat,
            root_cost,
            root_pieces,
            root_total,
        })
    }

    /// What any subset of elements costs (the element rows' `alone` and the budget plan).
    fn coster(&self, o: &Owners) -> SubsetCoster {
        SubsetCoster {
            owned: o.owned.clone(),
            root_count: o.root_count.clone(),
            groups: o.group_list.clone(),
            global: o.global,
            forced: if o.root_count.contains_key(&o.untagged) || o.split_root {
                vec![o.untagged]
            } else {
                vec![]
            },
            table_bytes_per_root_instance: std::mem::size_of::<motu_abi::TlasRecord>() as u64,
            image: self.input.floor_image,
            whole_table_bytes: whole_table_bytes(self.view),
        }
    }

    /// A row per label, then the shared row (phase `element_rows`, which goes on into
    /// [`Self::variants`]'s as-compiled variant).
    fn element_rows(
        &mut self,
        g: &Graph<'_>,
        o: &Owners,
        f: &Flattened,
        coster: &SubsetCoster,
    ) -> Result<Vec<ElementReport>, ReportError> {
        let t_rows = std::time::Instant::now();
        let sizes = self.sizes;
        let mut elements = Vec::new();
        let mut share_sum = Cost::default();
        for &l in &o.labels {
            let n_root = o.root_count.get(&l).copied().unwrap_or(0);
            let mut ml = o.owned.get(&l).copied().unwrap_or_default();
            ml.instance_buffer_bytes += n_root * crate::sizes::INSTANCE_RECORD_SIZE_BYTES;
            let share = Cost {
                // u128: AS bytes × instances can pass u64 at Moana scale.
                tlas_bytes: (u128::from(f.root_cost.tlas_bytes) * u128::from(n_root)
                    / u128::from(f.root_total)) as u64,
                ..Default::default()
            };
            ml.tlas_bytes += share.tlas_bytes;
            ml.instances += n_root;
            ml.seal();
            share_sum.tlas_bytes += share.tlas_bytes;
            let fl = f.flat.get(&l).copied().unwrap_or_default();
            let (sl_tlas, _) = tlas_cost(sizes, fl.tri_instances)?;
            let alone = if n_root > 0 {
                Some(coster.cost(&[l], sizes)?)
            } else {
                None
            };
            elements.push(ElementReport {
                name: o.name_of(self.input, l),
                id: (l != o.untagged).then_some(l),
                kind: if l == o.untagged {
                    "untagged"
                } else {
                    "element"
                }
                .into(),
                root_instances: n_root,
                flattened_instances: fl.tri_instances,
                instanced_triangles: fl.instanced_triangles,
                unique_triangles: o.unique_tris.get(&l).copied().unwrap_or(0),
                meshes: o.mesh_counts.get(&l).copied().unwrap_or(0),
                ml,
                sl_tlas_bytes: sl_tlas.tlas_total_bytes(),
                alone,
            });
        }
        // The rounding rest of the root TLAS's shares goes to the element with most root
        // instances.
        let rest = f.root_cost.tlas_bytes.saturating_sub(share_sum.tlas_bytes);
        if let Some(e) = elements
            .iter_mut()
            .filter(|e| e.root_instances > 0)
            .max_by_key(|e| e.root_instances)
        {
            e.ml.tlas_bytes += rest;
            e.ml.seal();
            share_sum.tlas_bytes += rest;
        }
        elements.push(shared_row(g, o, f, share_sum));
        self.timings
            .add("element_rows", t_rows.elapsed().as_secs_f64() * 1e3);
        Ok(elements)
    }

    /// `as_compiled` (timed with the element rows, as it always was), then the flattened
    /// variants (phase `variants`).
    fn variants(
        &mut self,
        g: &Graph<'_>,
        f: &Flattened,
        elements: &[ElementReport],
    ) -> Result<Vec<VariantReport>, ReportError> {
        let t_rows = std::time::Instant::now();
        let (input, sizes) = (self.input, self.sizes);
        let root = self.view.root_tlas;
        let root_rec = self.view.tlases[root as usize];
        let as_compiled = VariantReport {
            name: "as_compiled".into(),
            levels: input.levels.clone(),
            top_instances: u64::from(root_rec.instance_count),
            top_tlas_pieces: f.root_pieces,
            exceeds_max_instance_count: u64::from(root_rec.instance_count)
                > sizes.max_instance_count(),
            cost: Cost::sum(elements.iter().map(|e| &e.ml)).rendered_at(input.floor_image),
        };
        if as_compiled.exceeds_max_instance_count {
            self.warnings.push(format!(
                "the root TLAS has {} instances, over this device's maxInstanceCount {}: reimport with --max-instances",
                root_rec.instance_count,
                sizes.max_instance_count()
            ));
        }
        self.timings
            .add("element_rows", t_rows.elapsed().as_secs_f64() * 1e3);
        let t_variants = std::time::Instant::now();
        let mut variants = vec![as_compiled];
        for (name, levels) in [("levels_2", 2u32), ("sl", 1)] {
            variants.push(flattened_variant(
                g,
                root,
                name,
                levels,
                sizes,
                input.floor_image,
            )?);
        }
        self.timings
            .add("variants", t_variants.elapsed().as_secs_f64() * 1e3);
        Ok(variants)
    }

    /// The floor the renderer enforces, from the same function and (on a device) the same
    /// driver size queries, over the hierarchy the streamer renders (large TLASes split into
    /// pieces at load time): phases `stream_split` (when not stored), `proxy_clusters`,
    /// `floor`, `persistent_tlas`.
    fn streaming_floor(
        &mut self,
        streaming: &mut StreamingReport,
        stored_split: Option<Option<motu_compile::StreamSplit>>,
        stored_clusters: Option<&[u8]>,
        stored_cap: Option<u32>,
    ) -> Result<(), ReportError> {
        let (view, sizes) = (self.view, self.sizes);
        let (fw, fh) = self.input.floor_image;
        let split = match stored_split {
            Some(split) => {
                self.sources.stream_split = if split.is_some() { "package" } else { "none" }.into();
                split
            }
            None => {
                let s = self.timings.time("stream_split", || {
                    motu_render::stream_split(view, stored_cap)
                })?;
                self.sources.stream_split = if s.is_some() { "computed" } else { "none" }.into();
                s
            }
        };
        let streamed = split.as_ref().map_or(*view, |s| s.view(view));
        let plan = self.timings.time("proxy_clusters", || {
            motu_gpu::StreamPlan::load(&streamed, stored_clusters, None)
        });
        self.sources.proxy_clusters = plan.source().as_str().into();
        let floor = self
            .timings
            .time("floor", || {
                motu_gpu::streaming_floor_planned(
                    &streamed,
                    &plan,
                    &FloorAdapter(sizes),
                    fw,
                    fh,
                    motu_gpu::StreamOptions::default().staging_bytes,
                )
            })
            .map_err(ReportError::Floor)?;
        streaming.stream_split = split.as_ref().map(|s| {
            let (tlases_split, pieces) = s.counts();
            StreamSplitReport {
                cap_instances: stored_cap.unwrap_or(motu_render::STREAM_SPLIT_INSTANCES),
                tlases_split,
                pieces,
            }
        });
        streaming.min_resident_bytes = floor.min_resident_bytes;
        streaming.floor = floor;
        streaming.mesh_bytes = motu_gpu::streamed_mesh_total_bytes(&streamed);
        streaming.persistent_tlas = self
            .timings
            .time("persistent_tlas", || {
                motu_gpu::persistent_tlas_estimate(
                    &streamed,
                    &FloorAdapter(sizes),
                    sizes.max_instance_count(),
                )
            })
            .map_err(ReportError::PersistentEstimate)?;
        Ok(())
    }

    /// The report from the phases' results.
    fn finish(
        self,
        f: &Flattened,
        elements: Vec<ElementReport>,
        variants: Vec<VariantReport>,
        budget: Option<crate::budget::BudgetReport>,
        streaming: StreamingReport,
    ) -> Report {
        let (view, input, sizes) = (self.view, self.input, self.sizes);
        let sl = f.flat.values().fold(Expansion::default(), |mut a, e| {
            a.tri_instances = a.tri_instances.saturating_add(e.tri_instances);
            a.instanced_triangles = a.instanced_triangles.saturating_add(e.instanced_triangles);
            a
        });
        let render_overhead = {
            let c = &variants[0].cost;
            motu_gpu::full_build_overhead(
                c.resident_bytes + c.build_transient_peak_bytes,
                input.floor_image.0,
                input.floor_image.1,
            )
        };
        Report {
            package: input.package.clone(),
            levels: input.levels.clone(),
            sizes: sizes.info(),
            max_instance_count: sizes.max_instance_count(),
            max_primitive_count: sizes.max_primitive_count(),
            unique_triangles: view
                .blases
                .iter()
                .filter(|b| b.kind == motu_abi::BLAS_TRIANGLES)
                .map(|b| u64::from(b.primitive_count))
                .sum(),
            instanced_triangles: sl.instanced_triangles,
            flattened_instances: sl.tri_instances,
            elements,
            variants,
            render_overhead,
            image_width: input.floor_image.0,
            image_height: input.floor_image.1,
            budget,
            streaming,
            warnings: self.warnings,
            provenance: Provenance {
                sources: self.sources,
                timings_ms: self.timings,
            },
        }
    }
}

/// The shared row: shared nodes, global tables, the root TLAS's record and scratch (what the
/// element shares `share_sum` left of it).
fn shared_row(g: &Graph<'_>, o: &Owners, f: &Flattened, share_sum: Cost) -> ElementReport {
    let mut shared = Cost::sum(o.group_list.iter().map(|(_, c)| c));
    shared.add(&o.global);
    let mut root_rest = f.root_cost;
    root_rest.tlas_bytes -= share_sum.tlas_bytes.min(root_rest.tlas_bytes);
    shared.add(&root_rest);
    let shared_tris: u64 = o
        .own
        .iter()
        .filter(|&(n, owner)| owner == SHARED && matches!(n, Node::Blas(_)))
        .map(|(n, _)| g.cost(n).blas_triangles)
        .sum();
    let shared_meshes = o
        .own
        .iter()
        .filter(|&(n, owner)| owner == SHARED && matches!(n, Node::Mesh(_)))
        .count();
    ElementReport {
        name: "shared".into(),
        id: None,
        kind: "shared".into(),
        root_instances: 0,
        flattened_instances: 0,
        instanced_triangles: 0,
        unique_triangles: shared_tris,
        meshes: shared_meshes as u64,
        ml: shared,
        sl_tlas_bytes: 0,
        alone: None,
    }
}

/// The element label of untagged root instances (after every real element id).
fn untagged_label(input: &ReportInput, view: &HierarchyView<'_>) -> u32 {
    let max_tag = view
        .instances
        .iter()
        .map(|i| i.element)
        .filter(|&e| e != NONE_U32)
        .max()
        .map_or(0, |e| e + 1);
    (input.element_names.len() as u32).max(max_tag)
}

/// Whether TLAS `t` holds root-level placements: below the root instances are untagged, but a
/// split root's pieces keep their instances' element tags.
fn holds_root_placements(counts: &BlasCounts, t: u32) -> bool {
    counts
        .tlas(t as usize)
        .iter()
        .any(|c| c.element != NONE_U32)
}

/// A root placement: (element label, BLAS, how many root instances place it so).
type Placement = (u32, u32, u64);

/// The root's placements labelled by element: the root TLAS's own instances and, through a
/// split root's PI BLASes (identity PIs into TLASes of tagged instances), the instances of its
/// pieces, which keep their elements' tags. Also returns the split's own nodes. Walks the BLAS
/// counts (one entry per BLAS and element), not the instances.
fn root_placements(
    view: &HierarchyView<'_>,
    counts: &BlasCounts,
    untagged: u32,
) -> (Vec<Placement>, Vec<Node>) {
    let mut labelled = Vec::new();
    let mut split_nodes = Vec::new();
    let mut todo = vec![view.root_tlas];
    let mut seen = std::collections::HashSet::new();
    while let Some(t) = todo.pop() {
        for c in counts.tlas(t as usize) {
            let b = &view.blases[c.blas as usize];
            let pis: &[PiRecord] = if b.kind == motu_abi::BLAS_AABBS {
                view.pis
                    .get(b.item_base as usize..(b.item_base + b.item_count) as usize)
                    .unwrap_or(&[])
            } else {
                &[]
            };
            // A PI BLAS of the split (tagged when all its pieces share an element).
            let is_split = !pis.is_empty()
                && pis.iter().all(|p| {
                    p.kind == motu_abi::PI_TLAS
                        && p.child_from_parent == motu_abi::IDENTITY_3X4
                        && p.target != view.root_tlas
                        && holds_root_placements(counts, p.target)
                });
            if !is_split {
                let e = c.element;
                labelled.push((if e == NONE_U32 { untagged } else { e }, c.blas, c.count));
                continue;
            }
            split_nodes.push(Node::Blas(c.blas));
            for p in pis {
                if seen.insert(p.target) {
                    split_nodes.push(Node::Tlas(p.target));
                    todo.push(p.target);
                }
            }
        }
    }
    (labelled, split_nodes)
}

/// The record tables a `--subset` render uploads whole (see `SubsetCoster::whole_table_bytes`).
fn whole_table_bytes(view: &HierarchyView<'_>) -> u64 {
    fn bytes<T>(n: usize) -> u64 {
        n as u64 * std::mem::size_of::<T>() as u64
    }
    bytes::<motu_abi::TlasRecord>(view.tlases.len() + 1)
        + bytes::<motu_abi::BlasRecord>(view.blases.len())
        + bytes::<motu_abi::GeometryRecord>(view.geometries.len())
        + bytes::<motu_abi::MeshRecord>(view.meshes.len())
        + bytes::<motu_abi::LodSelectorRecord>(view.lod_selectors.len())
        + bytes::<u32>(view.lod_levels.len())
}

/// The whole scene flattened to `levels` TLAS levels (see `cost` module docs).
fn flattened_variant(
    g: &Graph<'_>,
    root: u32,
    name: &str,
    levels: u32,
    sizes: &dyn SizeSource,
    image: (u32, u32),
) -> Result<VariantReport, ReportError> {
    let expanded = g.expansions(levels);
    let e = g.expand(g.tlas_blases(root), levels, &expanded);
    let (tri_blas, kept) = g.expansion_nodes(root, levels);
    let mut starts: Vec<Node> = tri_blas.iter().map(|&b| Node::Blas(b)).collect();
    starts.extend(kept.iter().map(|&t| Node::Tlas(t)));
    let mut c = Cost::sum(g.reachable(starts).iter().map(|&n| g.cost(n)));
    // Kept PIs sit in AABB BLASes of the top TLAS (split at maxPrimitiveCount).
    let mut top_instances = e.tri_instances;
    if e.kept_pis > 0 {
        let max_prims = sizes.max_primitive_count().max(1);
        let blases = e.kept_pis.div_ceil(max_prims);
        let full = blases - 1;
        let last = e.kept_pis - full * max_prims;
        for (count, times) in [(max_prims, full), (last, 1)] {
            if times == 0 {
                continue;
            }
            let shape = BlasShape::Aabbs {
                box_count: u32::try_from(count).unwrap_or(u32::MAX),
            };
            let mut one = blas_cost_of(sizes, &shape, 0)?;
            one.table_bytes += count * std::mem::size_of::<PiRecord>() as u64;
            one.seal();
            // One addition of `times` copies: a loop of 2^40 additions would not end.
            c.add_times(&one, times);
        }
        top_instances = top_instances.saturating_add(blases);
    }
    let (mut top, pieces) = tlas_cost(sizes, top_instances)?;
    top.table_bytes = top.table_bytes.saturating_add(
        (std::mem::size_of::<motu_abi::TlasRecord>() as u64).saturating_add(
            top_instances.saturating_mul(std::mem::size_of::<InstanceRecord>() as u64),
        ),
    );
    top.seal();
    c.add(&top);
    c.add(&g.global_tables());
    Ok(VariantReport {
        name: name.into(),
        levels: if levels == 1 {
            "sl".into()
        } else {
            levels.to_string()
        },
        top_instances,
        top_tlas_pieces: pieces,
        exceeds_max_instance_count: top_instances > sizes.max_instance_count(),
        cost: c.rendered_at(image),
    })
}
