//! Building a [`Report`] from a hierarchy: per-element costs, variants, budget and streaming.

use std::collections::{BTreeMap, HashMap};

use motu_abi::{HierarchyView, InstanceRecord, PiRecord, NONE_U32};
use serde::Serialize;

use crate::budget::{plan_budget, BudgetReport, SubsetCoster};
use crate::cost::{blas_cost_of, tlas_cost, Cost, Graph, Node};
use crate::owner::{Ownership, SHARED};
use crate::rows::{ElementReport, VariantReport};
use crate::sizes::{BlasShape, SizeSource, SizeSourceInfo};
use crate::streaming::{streaming_report, FloorAdapter, StreamSplitReport, StreamingReport};
use crate::timing::{PhaseTimings, Provenance, ReportSources};
use crate::ReportError;
use motu_compile::blas_counts::BlasCounts;

/// What the report needs besides the tables (a package's meta, or hand-made in tests).
#[derive(Clone, Debug, Default)]
pub struct ReportInput {
    /// Shown as the report's subject (the package path).
    pub package: String,
    /// How the package was compiled (`ml`, `sl`, a number).
    pub levels: String,
    /// Element names by element id.
    pub element_names: Vec<String>,
    /// Image size the streaming floor and every full-build peak are computed for (frame
    /// buffers scale with it).
    pub floor_image: (u32, u32),
}

/// Image size of the streaming floor when the package has no camera.
pub const DEFAULT_FLOOR_IMAGE: (u32, u32) = (640, 480);

// The GPU crate's reports as `motu_render::stats` writes them (their JSON keys live there).
fn overhead_json<S: serde::Serializer>(
    v: &motu_gpu::FullBuildOverhead,
    s: S,
) -> Result<S::Ok, S::Error> {
    motu_render::stats::FullBuildOverhead::from(v).serialize(s)
}

/// The VRAM-budget report (`motu report --json` prints it as one object).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Report {
    pub package: String,
    /// `levels` as compiled.
    pub levels: String,
    pub sizes: SizeSourceInfo,
    pub max_instance_count: u64,
    pub max_primitive_count: u64,
    pub unique_triangles: u64,
    pub instanced_triangles: u64,
    pub flattened_instances: u64,
    /// Elements in id order, then `untagged` (if any), then `shared`.
    pub elements: Vec<ElementReport>,
    /// `as_compiled`, `levels_2`, `sl`.
    pub variants: Vec<VariantReport>,
    pub budget: Option<BudgetReport>,
    pub streaming: StreamingReport,
    /// What the whole scene's full build needs besides its structures at the report's image
    /// size (`image_width × image_height`): the `render_overhead_bytes` of `as_compiled`.
    #[serde(serialize_with = "overhead_json")]
    pub render_overhead: motu_gpu::FullBuildOverhead,
    /// The image every peak and the streaming floor are computed for (`--width`/`--height`,
    /// else the package camera's).
    pub image_width: u32,
    pub image_height: u32,
    pub warnings: Vec<String>,
    /// Where the stored inputs came from and each phase's wall time (`sources`,
    /// `timings_ms`); not compared.
    #[serde(flatten)]
    pub provenance: Provenance,
}

impl Report {
    /// The variant named `name`.
    pub fn variant(&self, name: &str) -> Option<&VariantReport> {
        self.variants.iter().find(|v| v.name == name)
    }
    /// The as-compiled totals.
    pub fn total(&self) -> Cost {
        self.variant("as_compiled")
            .map(|v| v.cost)
            .unwrap_or_default()
    }
}

/// Builds the report for a package (see [`build_report_from_view`]); the streaming floor is
/// for the first camera's image size.
pub fn build_report(
    pkg: &motu_pack::ScenePackage,
    sizes: &dyn SizeSource,
    budget_bytes: Option<u64>,
) -> Result<Report, ReportError> {
    build_report_at(pkg, sizes, budget_bytes, None)
}

/// [`build_report`] with the streaming floor for `floor_image` (width, height; `None`: the
/// first camera's size, else [`DEFAULT_FLOOR_IMAGE`]).
pub fn build_report_at(
    pkg: &motu_pack::ScenePackage,
    sizes: &dyn SizeSource,
    budget_bytes: Option<u64>,
    floor_image: Option<(u32, u32)>,
) -> Result<Report, ReportError> {
    let meta = pkg.meta();
    let input = ReportInput {
        package: pkg.path().to_string(),
        levels: meta.levels.clone(),
        element_names: meta.elements.iter().map(|e| e.name.clone()).collect(),
        floor_image: floor_image.unwrap_or_else(|| {
            meta.cameras
                .first()
                .map_or(DEFAULT_FLOOR_IMAGE, |c| (c.width.max(1), c.height.max(1)))
        }),
    };
    let mut timings = PhaseTimings::default();
    let view = pkg.view()?;
    // The cap a streamed render of the package splits at by default: the one its import
    // recorded (`motu import --stream-split-instances`).
    let (cap, _) = motu_render::package_split_cap(pkg, None);
    let split = timings.time("stream_split_read", || {
        motu_render::stored_stream_split_or_none(pkg, &view, cap)
    })?;
    // The proxy clusters the import stored (checked TLAS by TLAS against the split hierarchy).
    let clusters = motu_render::stored_proxy_clusters(pkg);
    let counts = timings.time("blas_counts_read", || stored_blas_counts(pkg, &view));
    let stored = Stored {
        split,
        clusters,
        counts,
        cap: Some(cap),
        timings,
        references_checked: true,
    };
    build(&view, &input, sizes, budget_bytes, stored)
}

/// The package's BLAS counts (`blas_counts` section) where they are this view's; `None` (a
/// warning where a section was there) otherwise.
fn stored_blas_counts(
    pkg: &motu_pack::ScenePackage,
    view: &HierarchyView<'_>,
) -> Option<BlasCounts> {
    let bytes = match pkg.stored_blas_counts() {
        Ok(b) => b?,
        Err(e) => {
            tracing::warn!(error = %e, "the package's BLAS counts cannot be read; counted again");
            return None;
        }
    };
    let counts = motu_compile::blas_counts::decode_section(bytes, view);
    if counts.is_none() {
        tracing::warn!(
            "the package's BLAS counts are not a table this reader knows or not its \
             hierarchy's; counted again"
        );
    }
    counts
}

/// What a package stored for its readers: the stream split (`None`: split here), the proxy
/// clusters' section (`None`: made here), the BLAS counts (`None`: counted here) and the split
/// cap it recorded (`None`: [`motu_render::STREAM_SPLIT_INSTANCES`]); and the time spent
/// reading them.
#[derive(Default)]
struct Stored<'p> {
    split: Option<Option<motu_compile::StreamSplit>>,
    clusters: Option<&'p [u8]>,
    cap: Option<u32>,
    counts: Option<BlasCounts>,
    timings: PhaseTimings,
    /// The view passed `check_references` (a package's, when it was opened).
    references_checked: bool,
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
pub(crate) type Placement = (u32, u32, u64);

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

/// Builds the report from hierarchy tables. Sizes are asked of `sizes` for every BLAS and TLAS
/// (sources cache repeats). O(nodes × elements sharing them).
pub fn build_report_from_view(
    view: &HierarchyView<'_>,
    input: &ReportInput,
    sizes: &dyn SizeSource,
    budget_bytes: Option<u64>,
) -> Result<Report, ReportError> {
    build(view, input, sizes, budget_bytes, Stored::default())
}

/// [`build_report_from_view`] with what the package stored (the stream split, the proxy
/// clusters).
fn build(
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
        mut timings,
        references_checked,
    } = stored;
    let mut sources = ReportSources {
        blas_counts: if stored_counts.is_some() {
            "package"
        } else {
            "computed"
        }
        .into(),
        ..Default::default()
    };
    let counts = match stored_counts {
        Some(c) => c,
        None => timings.time("blas_counts", || BlasCounts::of(view)),
    };
    let g = timings.time("graph", || {
        Graph::new(*view, sizes, counts, references_checked)
    })?;
    let mut warnings = Vec::new();
    let root = view.root_tlas;
    let root_rec = view.tlases[root as usize];
    let untagged = untagged_label(input, view);
    let t_own = std::time::Instant::now();
    let (labelled, split_nodes) = root_placements(view, &g.counts, untagged);
    let root_blases: Vec<(u32, u32)> = labelled.iter().map(|&(l, b, _)| (l, b)).collect();
    let mut own = Ownership::compute(&g, &root_blases);
    // A split root's skeleton (the PI BLASes into its pieces, the piece TLASes) is needed by
    // every subset, like untagged root instances.
    let split_root = !split_nodes.is_empty();
    for n in split_nodes {
        own.claim(n, untagged);
    }

    // Labels present, in id order (named elements with no instances still get a row).
    let mut labels: Vec<u32> = (0..input.element_names.len() as u32).collect();
    for &(l, _, _) in &labelled {
        if !labels.contains(&l) {
            labels.push(l);
        }
    }
    if split_root && !labels.contains(&untagged) {
        labels.push(untagged);
    }
    labels.sort_unstable();
    let name_of = |l: u32| -> String {
        if l == untagged {
            "(untagged)".into()
        } else {
            input
                .element_names
                .get(l as usize)
                .cloned()
                .unwrap_or_else(|| format!("element#{l}"))
        }
    };
    if labels
        .iter()
        .any(|&l| l != untagged && l as usize >= input.element_names.len())
    {
        warnings.push("root instances name element ids the package's meta does not list".into());
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
    timings.add("ownership", t_own.elapsed().as_secs_f64() * 1e3);

    // Flattening per element (SL) and for the whole scene.
    let t_flat = std::time::Instant::now();
    let expanded_sl = g.expansions(1);
    let mut flat: BTreeMap<u32, crate::cost::Expansion> = BTreeMap::new();
    for &(l, b, n) in &labelled {
        let e = g.expand(std::iter::once((b, n)), 1, &expanded_sl);
        let f = flat.entry(l).or_default();
        f.tri_instances = f.tri_instances.saturating_add(e.tri_instances);
        f.instanced_triangles = f.instanced_triangles.saturating_add(e.instanced_triangles);
    }

    // The root TLAS as compiled, its share per element by root instance count.
    let (mut root_cost, root_pieces) = tlas_cost(sizes, u64::from(root_rec.instance_count))?;
    root_cost.table_bytes += std::mem::size_of::<motu_abi::TlasRecord>() as u64;
    // Instance buffer and count are attributed to elements with their instance records.
    root_cost.instance_buffer_bytes = 0;
    root_cost.instances = 0;
    root_cost.seal();
    // Shared by root placements (a split root's pieces' instances included).
    let root_total = labelled.iter().map(|p| p.2).sum::<u64>().max(1);
    timings.add("flatten_elements", t_flat.elapsed().as_secs_f64() * 1e3);

    let coster = SubsetCoster {
        owned: owned.clone(),
        root_count: root_count.clone(),
        groups: group_list.clone(),
        global,
        forced: if root_count.contains_key(&untagged) || split_root {
            vec![untagged]
        } else {
            vec![]
        },
        table_bytes_per_root_instance: std::mem::size_of::<motu_abi::TlasRecord>() as u64,
        image: input.floor_image,
        whole_table_bytes: whole_table_bytes(view),
    };

    let t_rows = std::time::Instant::now();
    let mut elements = Vec::new();
    let mut share_sum = Cost::default();
    for &l in &labels {
        let n_root = root_count.get(&l).copied().unwrap_or(0);
        let mut ml = owned.get(&l).copied().unwrap_or_default();
        ml.instance_buffer_bytes += n_root * crate::sizes::INSTANCE_RECORD_SIZE_BYTES;
        let share = Cost {
            // u128: AS bytes × instances can pass u64 at Moana scale.
            tlas_bytes: (u128::from(root_cost.tlas_bytes) * u128::from(n_root)
                / u128::from(root_total)) as u64,
            ..Default::default()
        };
        ml.tlas_bytes += share.tlas_bytes;
        ml.instances += n_root;
        ml.seal();
        share_sum.tlas_bytes += share.tlas_bytes;
        let f = flat.get(&l).copied().unwrap_or_default();
        let (sl_tlas, _) = tlas_cost(sizes, f.tri_instances)?;
        let alone = if n_root > 0 {
            Some(coster.cost(&[l], sizes)?)
        } else {
            None
        };
        elements.push(ElementReport {
            name: name_of(l),
            id: (l != untagged).then_some(l),
            kind: if l == untagged { "untagged" } else { "element" }.into(),
            root_instances: n_root,
            flattened_instances: f.tri_instances,
            instanced_triangles: f.instanced_triangles,
            unique_triangles: unique_tris.get(&l).copied().unwrap_or(0),
            meshes: mesh_counts.get(&l).copied().unwrap_or(0),
            ml,
            sl_tlas_bytes: sl_tlas.tlas_total_bytes(),
            alone,
        });
    }
    // The rounding rest of the root TLAS's shares goes to the element with most root instances.
    let rest = root_cost.tlas_bytes.saturating_sub(share_sum.tlas_bytes);
    if let Some(e) = elements
        .iter_mut()
        .filter(|e| e.root_instances > 0)
        .max_by_key(|e| e.root_instances)
    {
        e.ml.tlas_bytes += rest;
        e.ml.seal();
        share_sum.tlas_bytes += rest;
    }
    // The shared row: shared nodes, global tables, the root TLAS's record and scratch.
    let mut shared = Cost::sum(group_list.iter().map(|(_, c)| c));
    shared.add(&global);
    let mut root_rest = root_cost;
    root_rest.tlas_bytes -= share_sum.tlas_bytes.min(root_rest.tlas_bytes);
    shared.add(&root_rest);
    let shared_tris: u64 = own
        .iter()
        .filter(|&(n, o)| o == SHARED && matches!(n, Node::Blas(_)))
        .map(|(n, _)| g.cost(n).blas_triangles)
        .sum();
    let shared_meshes = own
        .iter()
        .filter(|&(n, o)| o == SHARED && matches!(n, Node::Mesh(_)))
        .count();
    elements.push(ElementReport {
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
    });

    // Variants.
    let as_compiled = {
        let c = Cost::sum(elements.iter().map(|e| &e.ml)).rendered_at(input.floor_image);
        VariantReport {
            name: "as_compiled".into(),
            levels: input.levels.clone(),
            top_instances: u64::from(root_rec.instance_count),
            top_tlas_pieces: root_pieces,
            exceeds_max_instance_count: u64::from(root_rec.instance_count)
                > sizes.max_instance_count(),
            cost: c,
        }
    };
    if as_compiled.exceeds_max_instance_count {
        warnings.push(format!(
            "the root TLAS has {} instances, over this device's maxInstanceCount {}: reimport with --max-instances",
            root_rec.instance_count,
            sizes.max_instance_count()
        ));
    }
    timings.add("element_rows", t_rows.elapsed().as_secs_f64() * 1e3);
    let t_variants = std::time::Instant::now();
    let mut variants = vec![as_compiled];
    for (name, levels) in [("levels_2", 2u32), ("sl", 1)] {
        variants.push(flattened_variant(
            &g,
            root,
            name,
            levels,
            sizes,
            input.floor_image,
        )?);
    }
    timings.add("variants", t_variants.elapsed().as_secs_f64() * 1e3);
    let sl = flat
        .values()
        .fold(crate::cost::Expansion::default(), |mut a, e| {
            a.tri_instances = a.tri_instances.saturating_add(e.tri_instances);
            a.instanced_triangles = a.instanced_triangles.saturating_add(e.instanced_triangles);
            a
        });

    let mut streaming = timings.time("streaming_rows", || {
        streaming_report(&g, &own, &elements, &variants[0].cost, &root_cost, &name_of)
    });
    // The floor the renderer enforces, from the same function and (on a device) the same
    // driver size queries.
    let (fw, fh) = input.floor_image;
    // The hierarchy the streamer renders: large TLASes split into pieces at load time.
    let split = match stored_split {
        Some(split) => {
            sources.stream_split = if split.is_some() { "package" } else { "none" }.into();
            split
        }
        None => {
            let s = timings.time("stream_split", || {
                motu_render::stream_split(view, stored_cap)
            })?;
            sources.stream_split = if s.is_some() { "computed" } else { "none" }.into();
            s
        }
    };
    let streamed = split.as_ref().map_or(*view, |s| s.view(view));
    let plan = timings.time("proxy_clusters", || {
        motu_gpu::StreamPlan::load(&streamed, stored_clusters, None)
    });
    sources.proxy_clusters = plan.source().as_str().into();
    let floor = timings
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
    streaming.persistent_tlas = timings
        .time("persistent_tlas", || {
            motu_gpu::persistent_tlas_estimate(
                &streamed,
                &FloorAdapter(sizes),
                sizes.max_instance_count(),
            )
        })
        .map_err(ReportError::PersistentEstimate)?;
    let t_budget = std::time::Instant::now();
    let budget = budget_bytes
        .map(|b| {
            plan_budget(
                b,
                &coster,
                &elements,
                &variants,
                sizes,
                &name_of,
                streaming.min_resident_bytes,
            )
        })
        .transpose()?;
    timings.add("budget", t_budget.elapsed().as_secs_f64() * 1e3);
    let info = sizes.info();
    let render_overhead = {
        let c = &variants[0].cost;
        motu_gpu::full_build_overhead(
            c.resident_bytes + c.build_transient_peak_bytes,
            input.floor_image.0,
            input.floor_image.1,
        )
    };
    Ok(Report {
        package: input.package.clone(),
        levels: input.levels.clone(),
        sizes: info,
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
        warnings,
        provenance: Provenance {
            sources,
            timings_ms: timings,
        },
    })
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
