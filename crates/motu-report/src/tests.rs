//! Tests over hand-made hierarchies (no package, no GPU unless noted).

use motu_abi::{
    BlasRecord, GeometryRecord, HierarchyView, InstanceRecord, MaterialRecord, MeshRecord,
    PiRecord, TlasRecord, BLAS_AABBS, BLAS_TRIANGLES, NONE_U32, NONE_U64, PI_TLAS,
};

use crate::*;

/// Owned tables with a builder; children are made before parents.
#[derive(Default, Clone)]
pub(crate) struct Scene {
    tlases: Vec<TlasRecord>,
    instances: Vec<InstanceRecord>,
    blases: Vec<BlasRecord>,
    geometries: Vec<GeometryRecord>,
    pis: Vec<PiRecord>,
    meshes: Vec<MeshRecord>,
    materials: Vec<MaterialRecord>,
    textures: Vec<motu_abi::TextureRecord>,
    texels: Vec<u32>,
    root: u32,
    names: Vec<String>,
}

const IDENTITY: [f32; 12] = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0];

impl Scene {
    pub fn new(names: &[&str]) -> Self {
        Self {
            materials: vec![MaterialRecord::default()],
            names: names.iter().map(|s| s.to_string()).collect(),
            ..Default::default()
        }
    }
    pub fn mesh(&mut self, triangles: u32) -> u32 {
        self.meshes.push(MeshRecord {
            vertex_count: triangles + 2,
            triangle_count: triangles,
            normals_offset: NONE_U64,
            element: NONE_U32,
            ..Default::default()
        });
        self.meshes.len() as u32 - 1
    }
    pub fn tri_blas(&mut self, meshes: &[u32]) -> u32 {
        let base = self.geometries.len() as u32;
        let mut prims = 0;
        for &m in meshes {
            self.geometries.push(GeometryRecord {
                mesh: m,
                _pad: [0; 3],
            });
            prims += self.meshes[m as usize].triangle_count;
        }
        self.blases.push(BlasRecord {
            kind: BLAS_TRIANGLES,
            item_base: base,
            item_count: meshes.len() as u32,
            level: 1,
            primitive_count: prims,
            ..Default::default()
        });
        self.blases.len() as u32 - 1
    }
    pub fn pi_blas(&mut self, targets: &[u32]) -> u32 {
        let base = self.pis.len() as u32;
        for &t in targets {
            self.pis.push(PiRecord {
                child_from_parent: IDENTITY,
                kind: PI_TLAS,
                target: t,
                ..Default::default()
            });
        }
        self.blases.push(BlasRecord {
            kind: BLAS_AABBS,
            item_base: base,
            item_count: targets.len() as u32,
            level: 1,
            primitive_count: targets.len() as u32,
            ..Default::default()
        });
        self.blases.len() as u32 - 1
    }
    /// A TLAS over `(blas, element)` instances.
    pub fn tlas(&mut self, instances: &[(u32, u32)]) -> u32 {
        let base = self.instances.len() as u32;
        for &(blas, element) in instances {
            self.instances.push(InstanceRecord {
                tlas_from_blas: IDENTITY,
                blas,
                element,
                ..Default::default()
            });
        }
        self.tlases.push(TlasRecord {
            instance_base: base,
            instance_count: instances.len() as u32,
            element: NONE_U32,
            ..Default::default()
        });
        self.root = self.tlases.len() as u32 - 1;
        self.tlases.len() as u32 - 1
    }
    pub fn view(&self) -> HierarchyView<'_> {
        HierarchyView {
            root_tlas: self.root,
            tlases: &self.tlases,
            instances: &self.instances,
            blases: &self.blases,
            geometries: &self.geometries,
            pis: &self.pis,
            lod_selectors: &[],
            lod_levels: &[],
            meshes: &self.meshes,
            materials: &self.materials,
            textures: &self.textures,
            texels: &self.texels,
        }
    }
    pub fn input(&self) -> ReportInput {
        ReportInput {
            package: "test".into(),
            levels: "ml".into(),
            element_names: self.names.clone(),
            floor_image: crate::report::DEFAULT_FLOOR_IMAGE,
        }
    }
    pub fn report(&self, sizes: &dyn SizeSource, budget: Option<u64>) -> Report {
        build_report_from_view(&self.view(), &self.input(), sizes, budget).expect("report")
    }
    /// The same scene with only the root instances of `elements`.
    pub fn subset(&self, elements: &[u32]) -> Scene {
        let mut s = self.clone();
        let r = s.tlases[s.root as usize];
        let keep: Vec<InstanceRecord> = self.instances[r.instance_range()]
            .iter()
            .filter(|i| elements.contains(&i.element))
            .copied()
            .collect();
        let base = s.instances.len() as u32;
        s.instances.extend_from_slice(&keep);
        s.tlases[s.root as usize].instance_base = base;
        s.tlases[s.root as usize].instance_count = keep.len() as u32;
        s
    }
}

/// Element 0 `trees`: 20 trees (a trunk + 50 leaves each) through PIs; element 1 `garden`:
/// a ground mesh and 30 bushes of 10 leaves. The leaf BLAS is shared.
pub(crate) fn forest() -> Scene {
    let mut s = Scene::new(&["trees", "garden"]);
    let leaf = s.mesh(100);
    let trunk = s.mesh(1000);
    let ground = s.mesh(5000);
    let leaf_b = s.tri_blas(&[leaf]);
    let trunk_b = s.tri_blas(&[trunk]);
    let ground_b = s.tri_blas(&[ground]);
    let mut tree = vec![(trunk_b, NONE_U32)];
    tree.extend(std::iter::repeat_n((leaf_b, NONE_U32), 50));
    let tree_t = s.tlas(&tree);
    let trees_pi = s.pi_blas(&[tree_t; 20]);
    let bush_t = s.tlas(&[(leaf_b, NONE_U32); 10]);
    let bush_pi = s.pi_blas(&[bush_t; 30]);
    s.tlas(&[(trees_pi, 0), (ground_b, 1), (bush_pi, 1)]);
    s
}

/// Three TLAS levels: root → 4 tiles (PIs) → 5 trees each (PIs) → 7 leaves + a trunk.
fn three_levels() -> Scene {
    let mut s = Scene::new(&["main"]);
    let leaf = s.mesh(64);
    let trunk = s.mesh(500);
    let leaf_b = s.tri_blas(&[leaf]);
    let trunk_b = s.tri_blas(&[trunk]);
    let mut tree = vec![(trunk_b, NONE_U32)];
    tree.extend(std::iter::repeat_n((leaf_b, NONE_U32), 7));
    let tree_t = s.tlas(&tree);
    let tile_pi = s.pi_blas(&[tree_t; 5]);
    let tile_t = s.tlas(&[(tile_pi, NONE_U32)]);
    let root_pi = s.pi_blas(&[tile_t; 4]);
    s.tlas(&[(root_pi, 0)]);
    s
}

/// buddha-fractal's shape: 25,250 instances of a 29,890-triangle mesh plus inline meshes.
pub(crate) fn buddha_like() -> Scene {
    let mut s = Scene::new(&["main", "buddha"]);
    let floor = s.mesh(2);
    let buddha = s.mesh(29_890);
    let floor_b = s.tri_blas(&[floor]);
    let buddha_b = s.tri_blas(&[buddha]);
    let mut root = vec![(floor_b, 0)];
    root.extend(std::iter::repeat_n((buddha_b, 1), 25_250));
    s.tlas(&root);
    s
}

fn lavapipe() -> ModelSizes {
    ModelSizes::new(&LAVAPIPE)
}

/// A model with a lowered `maxInstanceCount`.
struct Capped(ModelSizes, u64);
impl SizeSource for Capped {
    fn info(&self) -> SizeSourceInfo {
        self.0.info()
    }
    fn blas_sizes(&self, shape: &BlasShape) -> Result<AsSizes, ReportError> {
        self.0.blas_sizes(shape)
    }
    fn tlas_sizes(&self, n: u64) -> Result<AsSizes, ReportError> {
        assert!(n <= self.1, "a TLAS of {n} over the cap {}", self.1);
        self.0.tlas_sizes(n)
    }
    fn compacted_blas_bytes(&self, shape: &BlasShape, built: AsSizes) -> u64 {
        self.0.compacted_blas_bytes(shape, built)
    }
    fn max_instance_count(&self) -> u64 {
        self.1
    }
    fn max_primitive_count(&self) -> u64 {
        self.0.max_primitive_count()
    }
}

fn element<'r>(r: &'r Report, name: &str) -> &'r ElementReport {
    r.elements
        .iter()
        .find(|e| e.name == name)
        .unwrap_or_else(|| panic!("no row {name}"))
}

#[test]
fn forest_counts_ownership_and_flattening() {
    let r = forest().report(&lavapipe(), None);
    let trees = element(&r, "trees");
    assert_eq!(trees.root_instances, 1);
    assert_eq!(trees.flattened_instances, 20 * 51);
    assert_eq!(trees.instanced_triangles, 20 * (1000 + 50 * 100));
    assert_eq!(trees.unique_triangles, 1000, "the trunk; leaves are shared");
    let garden = element(&r, "garden");
    assert_eq!(garden.flattened_instances, 1 + 30 * 10);
    assert_eq!(garden.instanced_triangles, 5000 + 300 * 100);
    assert_eq!(garden.unique_triangles, 5000);
    let shared = element(&r, "shared");
    assert_eq!(shared.unique_triangles, 100);
    assert_eq!(shared.meshes, 1);
    assert_eq!(r.flattened_instances, 1020 + 301);
    assert_eq!(r.instanced_triangles, 120_000 + 35_000);
    assert_eq!(r.unique_triangles, 6100);
    // Trees own trunk mesh + BLAS, the tree TLAS and the PI BLAS.
    assert_eq!(trees.ml.blas_count, 2);
    assert_eq!(trees.ml.tlas_count, 1);
    assert_eq!(garden.ml.blas_count, 2);
    assert_eq!(garden.ml.tlas_count, 1);
    assert_eq!(shared.ml.blas_count, 1);
}

#[test]
fn rows_add_up_to_the_whole_and_match_an_independent_sum() {
    let p = &LAVAPIPE;
    let r = forest().report(&lavapipe(), None);
    let total = r.total();
    // Rows are parts of one render: the full build's overhead comes once, on the whole.
    let sum = Cost::sum(r.elements.iter().map(|e| &e.ml));
    assert!(r.elements.iter().all(|e| e.ml.render_overhead_bytes == 0));
    assert_eq!(
        sum.rendered_at((r.streaming.floor.width, r.streaming.floor.height)),
        total
    );
    // Independently: 3 triangle BLASes, 2 AABB BLASes, 3 TLASes, 3 meshes.
    let al = |b: u64| b.div_ceil(256) * 256;
    let blas_built = al(p.blas_triangles.eval(100))
        + al(p.blas_triangles.eval(1000))
        + al(p.blas_triangles.eval(5000))
        + al(p.blas_aabbs.eval(20))
        + al(p.blas_aabbs.eval(30));
    assert_eq!(total.blas_bytes, blas_built);
    assert_eq!(
        total.blas_compacted_bytes, blas_built,
        "lavapipe ratio is 1"
    );
    let tlas = al(p.tlas.eval(51)) + al(p.tlas.eval(10)) + al(p.tlas.eval(3));
    assert_eq!(total.tlas_bytes, tlas);
    assert_eq!(total.instance_buffer_bytes, (51 + 10 + 3) * 64);
    assert_eq!(total.instances, 64);
    let mesh_geo = |t: u64| (t + 2) * 12 + t * 12;
    assert_eq!(
        total.geometry_bytes,
        mesh_geo(100) + mesh_geo(1000) + mesh_geo(5000) + 50 * 24
    );
    use std::mem::size_of;
    let tables = 3 * size_of::<TlasRecord>()
        + 64 * size_of::<InstanceRecord>()
        + 5 * size_of::<BlasRecord>()
        + 3 * size_of::<GeometryRecord>()
        + 50 * size_of::<PiRecord>()
        + 3 * size_of::<MeshRecord>()
        + size_of::<MaterialRecord>();
    assert_eq!(total.table_bytes, tables as u64);
    assert_eq!(
        total.resident_bytes,
        total.geometry_bytes + blas_built + tlas + 64 * 64 + total.table_bytes
    );
    // Lavapipe gains nothing from compaction: only scratch (64 B) is transient.
    assert_eq!(total.build_transient_peak_bytes, 64);
    // With compaction (H200 model) the largest BLAS's uncompacted copy is transient.
    let h = &NVIDIA_H200;
    let r = forest().report(&ModelSizes::new(h), None);
    let built = al(h.blas_triangles.eval(5000));
    let compacted = al((h.blas_triangles.eval(5000) as f64 * 0.6).round() as u64);
    let scratch = h.blas_triangles_scratch.eval(5000);
    assert_eq!(
        r.total().build_transient_peak_bytes,
        (built + scratch - compacted).max(built)
    );
    assert!(r.total().blas_compacted_bytes < r.total().blas_bytes);
}

#[test]
fn variants_flatten_by_level_budget() {
    let s = three_levels();
    let r = s.report(&lavapipe(), None);
    let ml = r.variant("as_compiled").expect("ml");
    assert_eq!(ml.top_instances, 1);
    assert_eq!(ml.cost.tlas_count, 3);
    // --levels 2: tiles (depth 2) are inlined, trees (depth 1) kept: 20 PIs in one AABB BLAS.
    let l2 = r.variant("levels_2").expect("l2");
    assert_eq!(l2.top_instances, 1);
    assert_eq!(l2.cost.tlas_count, 2, "top + tree");
    assert_eq!(l2.cost.blas_count, 3, "AABB(20) + trunk + leaf");
    let aabb20 = LAVAPIPE.blas_aabbs.eval(20).div_ceil(256) * 256;
    assert!(l2.cost.blas_bytes >= aabb20);
    // sl: every placement in the top TLAS.
    let sl = r.variant("sl").expect("sl");
    assert_eq!(sl.top_instances, 4 * 5 * 8);
    assert_eq!(r.flattened_instances, 160);
    assert_eq!(sl.cost.tlas_count, 1);
    assert_eq!(sl.cost.blas_count, 2);
    assert!(!sl.exceeds_max_instance_count);
    assert_eq!(sl.levels, "sl");
    assert_eq!(r.instanced_triangles, 20 * (500 + 7 * 64));
    assert!(
        sl.cost.tlas_bytes > ml.cost.tlas_bytes,
        "flattening grows the TLAS"
    );
}

#[test]
fn sl_over_max_instance_count_is_split() {
    let sizes = Capped(lavapipe(), 100);
    let r = forest().report(&sizes, None);
    let sl = r.variant("sl").expect("sl");
    assert_eq!(sl.top_instances, 1321);
    assert!(sl.exceeds_max_instance_count);
    assert_eq!(sl.top_tlas_pieces, 14);
    // 14 pieces + the joining 1-instance TLAS.
    assert_eq!(sl.cost.tlas_count, 15);
    let text = render_text(&r);
    assert!(text.contains("exceeds maxInstanceCount 100"), "{text}");
    assert!(text.contains("needs 14 TLASes"), "{text}");
}

/// The record tables a `--subset` render uploads whole besides the subset's own: the
/// package's TLAS (and the filtered root's), BLAS, geometry, mesh and LOD records
/// (`RootSubset` keeps only the instance and PI records its root reaches).
fn whole_tables(s: &Scene) -> u64 {
    let v = s.view();
    ((v.tlases.len() + 1) * std::mem::size_of::<motu_abi::TlasRecord>()
        + std::mem::size_of_val(v.blases)
        + std::mem::size_of_val(v.geometries)
        + std::mem::size_of_val(v.meshes)
        + std::mem::size_of_val(v.lod_selectors)
        + std::mem::size_of_val(v.lod_levels)) as u64
}

#[test]
fn subset_costs_equal_reports_of_the_subset_scene() {
    let s = forest();
    let r = s.report(&lavapipe(), Some(u64::MAX));
    let whole = whole_tables(&s);
    for (name, id) in [("trees", 0u32), ("garden", 1)] {
        let alone = element(&r, name).alone.expect("alone");
        let sub = s.subset(&[id]).report(&lavapipe(), None).total();
        assert_eq!(alone.table_bytes, sub.table_bytes + whole, "{name}");
        assert_eq!(
            alone.resident_bytes - alone.table_bytes,
            sub.resident_bytes - sub.table_bytes,
            "{name}"
        );
        assert_eq!(
            alone.build_transient_peak_bytes, sub.build_transient_peak_bytes,
            "{name}"
        );
        assert_eq!(alone.tlas_count, sub.tlas_count, "{name}");
        // Each renders on its own: the full build's overhead on top, at the report's image.
        assert_eq!(
            alone.peak_bytes,
            alone.resident_bytes
                + alone.build_transient_peak_bytes
                + motu_gpu::full_build_overhead(
                    alone.resident_bytes + alone.build_transient_peak_bytes,
                    r.streaming.floor.width,
                    r.streaming.floor.height
                )
                .total_bytes,
            "{name}"
        );
    }
    let total = r.total();
    let b = r.budget.expect("budget");
    assert!(b.scene_fits);
    let sg = b.suggestion.expect("suggestion");
    assert_eq!(sg.subset_arg, "--subset trees,garden");
    assert_eq!(sg.cost.resident_bytes, total.resident_bytes + whole);
    assert!((sg.triangle_fraction - 1.0).abs() < 1e-9);
}

#[test]
fn budget_picks_the_most_triangles_that_fit() {
    let s = forest();
    let r = s.report(&lavapipe(), None);
    let trees = element(&r, "trees").alone.expect("trees").peak_bytes;
    let garden = element(&r, "garden").alone.expect("garden").peak_bytes;
    // Trees have more instanced triangles; a budget between the two picks the one that fits.
    let (small, big) = if trees < garden {
        ("trees", garden)
    } else {
        ("garden", trees)
    };
    let r = s.report(&lavapipe(), Some(big - 1));
    let b = r.budget.as_ref().expect("budget");
    assert!(!b.scene_fits);
    let sg = b.suggestion.as_ref().expect("one fits");
    assert_eq!(sg.elements, vec![small.to_string()]);
    assert_eq!(sg.subset_arg, format!("--subset {small}"));
    assert!(sg.cost.peak_bytes < big);
    assert_eq!(b.elements.iter().filter(|e| e.fits).count(), 1);
    let text = render_text(&r);
    assert!(text.contains(&sg.subset_arg), "{text}");
    // Nothing fits: no suggestion, a note.
    let r = s.report(&lavapipe(), Some(1000));
    let b = r.budget.expect("budget");
    assert!(b.suggestion.is_none());
    assert!(!b.streaming_fits);
    assert!(
        b.notes.iter().any(|n| n.contains("no element fits")),
        "{:?}",
        b.notes
    );
}

/// Many elements with independent subtrees: greedy is used, fits, and is at least as good
/// as the best single element; with ≤ EXACT_LIMIT elements the exact answer beats greedy.
#[test]
fn greedy_and_exact_subsets_fit_the_budget() {
    let build = |n: u32| {
        let names: Vec<String> = (0..n).map(|i| format!("e{i}")).collect();
        let refs: Vec<&str> = names.iter().map(|s| s.as_str()).collect();
        let mut s = Scene::new(&refs);
        let shared = s.mesh(300);
        let shared_b = s.tri_blas(&[shared]);
        let mut root = Vec::new();
        for i in 0..n {
            let m = s.mesh(200 + 97 * ((i * 7) % 13));
            let b = s.tri_blas(&[m]);
            let mut inst = vec![(b, NONE_U32); (1 + i % 5) as usize];
            if i % 3 == 0 {
                inst.push((shared_b, NONE_U32));
            }
            let t = s.tlas(&inst);
            let pi = s.pi_blas(&vec![t; (1 + (i * 5) % 11) as usize]);
            root.push((pi, i));
        }
        s.tlas(&root);
        s
    };
    for n in [5u32, 20] {
        let s = build(n);
        // Half the structures, beside the render's own overhead.
        let full = s.report(&lavapipe(), None).total();
        let budget =
            full.render_overhead_bytes + (full.peak_bytes - full.render_overhead_bytes) / 2;
        let r = s.report(&lavapipe(), Some(budget));
        let b = r.budget.as_ref().expect("budget");
        let sg = b.suggestion.as_ref().expect("some fit");
        assert_eq!(
            sg.method,
            if n as usize <= EXACT_LIMIT {
                "exact"
            } else {
                "greedy"
            }
        );
        assert!(sg.cost.peak_bytes <= budget);
        let best_single = r
            .elements
            .iter()
            .filter(|e| e.alone.is_some_and(|a| a.peak_bytes <= budget))
            .map(|e| e.instanced_triangles)
            .max()
            .unwrap_or(0);
        assert!(sg.instanced_triangles >= best_single);
        // The suggested subset really costs that: rebuild it as a scene.
        let ids: Vec<u32> = sg
            .elements
            .iter()
            .map(|n| n[1..].parse().expect("id"))
            .collect();
        let sub = s.subset(&ids).report(&lavapipe(), None);
        // Its structures; its tables plus what `--subset` uploads whole.
        let c = sub.total();
        assert_eq!(sg.cost.table_bytes, c.table_bytes + whole_tables(&s));
        assert_eq!(
            sg.cost.resident_bytes - sg.cost.table_bytes,
            c.resident_bytes - c.table_bytes
        );
        assert_eq!(sub.instanced_triangles, sg.instanced_triangles);
    }
}

#[test]
fn untagged_root_instances_and_unknown_ids_get_rows() {
    let mut s = Scene::new(&["a"]);
    let m = s.mesh(10);
    let b = s.tri_blas(&[m]);
    s.tlas(&[(b, 0), (b, NONE_U32), (b, 3)]);
    let r = s.report(&lavapipe(), Some(u64::MAX));
    let names: Vec<&str> = r.elements.iter().map(|e| e.name.as_str()).collect();
    assert_eq!(names, ["a", "element#3", "(untagged)", "shared"]);
    assert!(!r.warnings.is_empty());
    let sg = r.budget.expect("budget").suggestion.expect("fits");
    assert!(!sg.subset_arg.contains("untagged"));
}

#[test]
fn cycles_and_broken_references_are_errors_not_panics() {
    let mut s = Scene::new(&["a"]);
    let pi = s.pi_blas(&[1]);
    s.tlas(&[(pi, 0)]); // TLAS 0 → PI → TLAS 1
    let pi2 = s.pi_blas(&[0]);
    s.tlas(&[(pi2, 0)]); // TLAS 1 → PI → TLAS 0
    let err = build_report_from_view(&s.view(), &s.input(), &lavapipe(), None).expect_err("cycle");
    assert!(err.to_string().contains("cycle"), "{err}");
    let mut s = forest();
    s.instances[0].blas = 999;
    let err =
        build_report_from_view(&s.view(), &s.input(), &lavapipe(), None).expect_err("bad ref");
    assert!(err.to_string().contains("out of range"), "{err}");
}

#[test]
fn empty_scene_reports_zeroes() {
    let mut s = Scene::new(&[]);
    s.tlas(&[]);
    let r = s.report(&lavapipe(), Some(1 << 20));
    assert_eq!(r.flattened_instances, 0);
    assert_eq!(r.elements.len(), 1);
    assert!(r.budget.expect("budget").suggestion.is_none());
    let _ = render_text(&s.report(&lavapipe(), None));
    let _ = render_html(&s.report(&lavapipe(), None));
}

#[test]
fn json_is_one_object_with_the_documented_keys() {
    let r = buddha_like().report(&ModelSizes::new(&NVIDIA_H200), Some(64 << 20));
    let v = serde_json::to_value(&r).expect("json");
    for k in [
        "package",
        "levels",
        "sizes",
        "max_instance_count",
        "max_primitive_count",
        "unique_triangles",
        "instanced_triangles",
        "flattened_instances",
        "elements",
        "variants",
        "budget",
        "streaming",
        "render_overhead",
        "image_width",
        "image_height",
        "warnings",
        "sources",
        "timings_ms",
    ] {
        assert!(v.get(k).is_some(), "missing key {k}");
    }
    // Tables made from the view: nothing stored.
    assert_eq!(v["sources"]["blas_counts"], "computed");
    assert_eq!(v["sources"]["proxy_clusters"], "computed");
    for phase in ["blas_counts", "graph", "ownership", "variants", "floor"] {
        assert!(
            v["timings_ms"][phase].as_f64().is_some_and(|ms| ms >= 0.0),
            "missing timings_ms.{phase}"
        );
    }
    for k in [
        "frame_bytes",
        "staging_bytes",
        "allocator_slack_bytes",
        "total_bytes",
    ] {
        assert!(
            v["render_overhead"].get(k).is_some(),
            "missing render_overhead.{k}"
        );
    }
    assert_eq!(
        v["variants"][0]["cost"]["render_overhead_bytes"],
        v["render_overhead"]["total_bytes"]
    );
    let e = &v["elements"][1];
    assert_eq!(e["name"], "buddha");
    assert_eq!(e["root_instances"], 25_250);
    for k in [
        "geometry_bytes",
        "blas_bytes",
        "blas_compacted_bytes",
        "tlas_bytes",
        "instance_buffer_bytes",
        "table_bytes",
        "build_scratch_peak_bytes",
        "render_overhead_bytes",
        "resident_bytes",
        "peak_bytes",
    ] {
        assert!(e["ml"].get(k).is_some(), "missing ml.{k}");
    }
    assert_eq!(v["variants"][2]["name"], "sl");
    assert_eq!(v["sizes"]["kind"], "model");
    assert!(v["budget"]["suggestion"]["subset_arg"]
        .as_str()
        .is_some_and(|s| s.starts_with("--subset ")));
    // H200 model: compaction shrinks BLASes.
    assert!(r.total().blas_compacted_bytes < r.total().blas_bytes);
}

#[test]
fn html_is_self_contained_and_escapes_names() {
    let mut s = forest();
    s.names[1] = "<garden & \"co\">".into();
    let html = render_html(&s.report(&lavapipe(), Some(1 << 20)));
    assert!(html.starts_with("<!DOCTYPE html>"));
    for id in ["chart-elements", "chart-variants", "chart-budget"] {
        assert!(html.contains(&format!("id=\"{id}\"")), "{id}");
    }
    assert!(html.contains("&lt;garden &amp; &quot;co&quot;&gt;"));
    assert!(!html.contains("<garden"));
    for remote in ["http://", "https://", "src=", "@import", "url("] {
        assert!(!html.contains(remote), "network asset marker {remote}");
    }
}

/// The model against the real driver: a sweep of sizes and whole reports of the hand-made
/// scenes, within 15% (lavapipe: exact). Skips loudly without a ray-tracing device.
#[test]
fn model_matches_driver_within_15_percent() {
    let Some(ctx) = motu_gpu::testutil::context_or_skip(
        "report_model_vs_driver",
        motu_gpu::Requirement::RayTracing,
    ) else {
        return;
    };
    let gpu = GpuSizes::with_context(ctx.clone());
    let Some(preset) = preset_for_device(ctx.device_name()) else {
        eprintln!(
            "SKIPPED: report_model_vs_driver: no size preset was fitted on {} (run the fit_sizes example)",
            ctx.device_name()
        );
        return;
    };
    let model = ModelSizes::new(preset);
    let mut worst = (0.0f64, String::new());
    let mut check = |what: &str, m: u64, d: u64| {
        let e = relative_error(m, d);
        if e > worst.0 {
            worst = (e, format!("{what}: model {m} vs driver {d}"));
        }
        assert!(
            e <= 0.15,
            "{what} on {}: model {m} vs driver {d} ({:.1}%)",
            ctx.device_name(),
            e * 100.0
        );
    };
    for n in [1u32, 3, 10, 100, 777, 5000, 40_000, 300_000] {
        let tri = BlasShape::Triangles(vec![TriangleGeometry {
            vertex_count: n + 2,
            triangle_count: n,
            opaque: true,
        }]);
        let two = BlasShape::Triangles(vec![
            TriangleGeometry {
                vertex_count: n + 2,
                triangle_count: n,
                opaque: true,
            },
            TriangleGeometry {
                vertex_count: 50,
                triangle_count: 48,
                opaque: false,
            },
        ]);
        for (what, shape) in [
            ("triangles", tri),
            ("two geometries", two),
            ("aabbs", BlasShape::Aabbs { box_count: n }),
            (
                "non-opaque",
                BlasShape::Triangles(vec![TriangleGeometry {
                    vertex_count: n / 2 + 3,
                    triangle_count: n,
                    opaque: false,
                }]),
            ),
        ] {
            let d = gpu.blas_sizes(&shape).expect("driver");
            let m = model.blas_sizes(&shape).expect("model");
            check(what, m.size_bytes, d.size_bytes);
            check(what, m.build_scratch_bytes, d.build_scratch_bytes);
        }
        let d = gpu.tlas_sizes(u64::from(n)).expect("driver");
        let m = model.tlas_sizes(u64::from(n)).expect("model");
        check("tlas", m.size_bytes, d.size_bytes);
        check("tlas scratch", m.build_scratch_bytes, d.build_scratch_bytes);
    }
    for (name, s) in [
        ("forest", forest()),
        ("three_levels", three_levels()),
        ("buddha_like", buddha_like()),
    ] {
        let rd = s.report(&gpu, Some(1 << 30));
        let rm = s.report(&model, Some(1 << 30));
        assert_eq!(rd.sizes.kind, "driver");
        for (vd, vm) in rd.variants.iter().zip(&rm.variants) {
            let what = format!("{name} {}", vd.name);
            check(
                &format!("{what} BLAS"),
                vm.cost.blas_bytes,
                vd.cost.blas_bytes,
            );
            check(
                &format!("{what} TLAS"),
                vm.cost.tlas_bytes,
                vd.cost.tlas_bytes,
            );
            check(
                &format!("{what} peak"),
                vm.cost.peak_bytes,
                vd.cost.peak_bytes,
            );
        }
    }
    eprintln!(
        "model vs driver on {}: worst relative error {:.3}% ({})",
        ctx.device_name(),
        worst.0 * 100.0,
        worst.1
    );
    motu_gpu::testutil::assert_no_validation_errors(&ctx);
}

/// The text says what a peak is made of, and says so when streaming cannot go below the
/// full build (its floor holds the skeleton, a build, TLAS rebuilds and frame buffers at once).
#[test]
fn text_explains_the_peak_and_a_floor_over_it() {
    // Many big BLASes: the floor holds one of them, the full build all.
    let mut big = Scene::new(&["big"]);
    let root: Vec<(u32, u32)> = (0..64)
        .map(|_| {
            let m = big.mesh(50_000);
            (big.tri_blas(&[m]), 0)
        })
        .collect();
    big.tlas(&root);
    let mut seen = [false; 2];
    for s in [forest(), buddha_like(), three_levels(), big] {
        let r = s.report(&lavapipe(), None);
        let text = render_text(&r);
        assert!(text.contains("peak = resident"), "{text}");
        let over = r.streaming.min_resident_bytes >= r.total().peak_bytes;
        assert_eq!(text.contains("render without --stream"), over, "{text}");
        seen[usize::from(over)] = true;
    }
    assert_eq!(seen, [true, true], "both cases among the scenes");
}

#[test]
fn text_table_lists_every_row_and_variant() {
    let r = forest().report(&ModelSizes::new(&NVIDIA_H200), Some(200 << 10));
    // Models are fitted on plain builds: updatable TLAS sizes need a device.
    assert_eq!(r.streaming.persistent_tlas, None);
    let text = render_text(&r);
    assert!(!text.contains("persistent TLASes"), "{text}");
    // No TLAS over the streaming split's cap: no split line; one over it: the line.
    assert_eq!(r.streaming.stream_split, None);
    assert!(!text.contains("streaming splits"), "{text}");
    let mut split = r.clone();
    split.streaming.stream_split = Some(crate::StreamSplitReport {
        cap_instances: 1_000_000,
        tlases_split: 1,
        pieces: 12,
    });
    let line = render_text(&split);
    assert!(
        line.contains("streaming splits 1 TLAS over 1000000 instances into 12 pieces"),
        "{line}"
    );
    eprintln!("{text}");
    for needle in [
        "trees",
        "garden",
        "shared",
        "as_compiled (ml)",
        "levels_2 (2)",
        "sl (sl)",
        "Budget 200 KiB",
        "Streaming:",
    ] {
        assert!(text.contains(needle), "missing {needle}:\n{text}");
    }
    // Every table row has the same column count as its header (aligned columns).
    let lines: Vec<&str> = text.lines().collect();
    let header = lines
        .iter()
        .position(|l| l.starts_with("element"))
        .expect("header");
    let width = lines[header].len();
    for l in &lines[header + 2..header + 2 + r.elements.len()] {
        assert_eq!(l.chars().count(), width, "{l}");
    }
}

/// Where tests leave files for humans (screenshots): `MOTU_TEST_ARTIFACTS`, else
/// `target/<profile>/test-artifacts`.
fn artifacts_dir() -> std::path::PathBuf {
    let dir = std::env::var_os("MOTU_TEST_ARTIFACTS")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| {
            std::env::current_exe()
                .ok()
                .and_then(|exe| {
                    exe.parent()
                        .and_then(|deps| deps.parent())
                        .map(|p| p.join("test-artifacts"))
                })
                .unwrap_or_else(std::env::temp_dir)
        });
    std::fs::create_dir_all(&dir).expect("artifacts dir");
    dir
}

/// Runs Debian's headless chromium on `page` with `mode` (`--dump-dom` or `--screenshot=…`);
/// returns (stdout, stderr).
fn chromium(page: &std::path::Path, mode: &str) -> (String, String) {
    let profile = tempfile::tempdir().expect("profile dir");
    let out = std::process::Command::new("timeout")
        .arg("120")
        .arg("chromium")
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--enable-logging=stderr",
            "--v=0",
            "--window-size=1200,900",
        ])
        .arg(format!("--user-data-dir={}", profile.path().display()))
        .arg(mode)
        .arg(format!("file://{}", page.display()))
        .output()
        .expect("run chromium");
    assert!(
        out.status.success(),
        "chromium failed ({}): {}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    (
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Console lines that mean the page is broken: script errors, failed loads.
fn console_errors(stderr: &str) -> Vec<&str> {
    stderr
        .lines()
        .filter(|l| l.contains(":CONSOLE"))
        .filter(|l| {
            ["Uncaught", "Error", "Failed to load", "Refused"]
                .iter()
                .any(|w| l.contains(w))
        })
        .collect()
}

fn chromium_available() -> bool {
    let found = std::process::Command::new("chromium")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !found {
        if std::env::var("MOTU_REQUIRE_BROWSER").is_ok_and(|v| v.trim() == "1") {
            panic!("MOTU_REQUIRE_BROWSER=1 but chromium is not installed (apt-get install -y chromium)");
        }
        eprintln!("SKIPPED: chromium not installed: html_report_renders_in_headless_chromium");
    }
    found
}

/// The HTML report of a buddha-fractal-shaped scene in a real browser: the script runs to its
/// end without console errors, the charts are in the DOM, and the screenshot shows the bars.
/// A page that throws proves the console check can fail.
#[test]
fn html_report_renders_in_headless_chromium() {
    if !chromium_available() {
        return;
    }
    let dir = tempfile::tempdir().expect("tmp");
    // 8 MiB for the structures, beside the render's own overhead (frame buffers at 640×480).
    let overhead = buddha_like()
        .report(&lavapipe(), None)
        .total()
        .render_overhead_bytes;
    let r = buddha_like().report(&lavapipe(), Some(overhead + (8 << 20)));
    let page = dir.path().join("report.html");
    std::fs::write(&page, render_html(&r)).expect("write html");

    let (dom, log) = chromium(&page, "--dump-dom");
    let errors = console_errors(&log);
    assert!(errors.is_empty(), "console errors: {errors:#?}");
    assert!(
        dom.contains(r#"data-ready="1""#),
        "the script did not finish:\n{dom}"
    );
    for id in ["chart-elements", "chart-variants", "chart-budget"] {
        assert!(dom.contains(&format!(r#"id="{id}""#)), "chart {id} missing");
    }
    let bars = dom.matches(r#"<rect class="bar "#).count();
    assert!(bars >= 3 * 3, "{bars} bars");
    assert!(
        dom.contains(&format!(r#"<span id="bar-count">{bars}</span>"#)),
        "script counted bars differently"
    );
    assert!(
        dom.contains(r#"id="subset-arg">--subset "#),
        "no subset suggestion in the page"
    );

    let shot = artifacts_dir().join("motu-report-buddha.png");
    let _ = std::fs::remove_file(&shot);
    let (_, log) = chromium(&page, &format!("--screenshot={}", shot.display()));
    assert!(console_errors(&log).is_empty());
    let decoder = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(&shot).expect("screenshot written"),
    ));
    let mut reader = decoder.read_info().expect("png");
    let mut buf = vec![0; reader.output_buffer_size().expect("size")];
    let info = reader.next_frame(&mut buf).expect("frame");
    assert_eq!((info.width, info.height), (1200, 900));
    let px = info.color_type.samples();
    // The geometry and BLAS segment colours (#4c78a8, #f58518) are on screen.
    let has = |rgb: [u8; 3]| buf.chunks(px).any(|p| p[..3] == rgb);
    assert!(
        has([0x4c, 0x78, 0xa8]) && has([0xf5, 0x85, 0x18]),
        "no chart bars in {}",
        shot.display()
    );
    eprintln!("screenshot: {}", shot.display());

    // Negative control: a throwing page is caught.
    let bad = dir.path().join("bad.html");
    std::fs::write(
        &bad,
        "<!DOCTYPE html><body><script>throw new Error('boom')</script></body>",
    )
    .expect("write");
    let (_, log) = chromium(&bad, "--dump-dom");
    assert!(
        !console_errors(&log).is_empty(),
        "the console check missed an uncaught error:\n{log}"
    );
}

/// Writes `s` as a real package (motu-pack), with `split`'s sections and meta entry if given.
fn write_package(
    s: &mut Scene,
    path: &std::path::Path,
    split: Option<motu_pack::StreamSplitMeta>,
) -> Option<motu_compile::StoredStreamSplit> {
    write_package_with(s, path, split, None)
}

/// [`write_package`] with a `blas_counts` section of these bytes.
fn write_package_with(
    s: &mut Scene,
    path: &std::path::Path,
    split: Option<motu_pack::StreamSplitMeta>,
    blas_counts: Option<&[u8]>,
) -> Option<motu_compile::StoredStreamSplit> {
    let writer = motu_package::PackageWriter::create(path, Default::default()).expect("writer");
    let geometry = motu_pack::PackageGeometry::new(writer);
    for m in &mut s.meshes {
        let t = m.triangle_count;
        let data = motu_scene::MeshData {
            positions: (0..m.vertex_count)
                .map(|i| [i as f32, (i % 2) as f32, 0.0])
                .collect(),
            normals: None,
            uvs: None,
            indices: (0..t).flat_map(|i| [0, i + 1, i + 2]).collect(),
        };
        let at = geometry.append_mesh(0, &data).expect("append");
        motu_pack::place_mesh_record(m, at);
    }
    let mut writer = geometry.take_writer().expect("writer back");
    let mut stored = None;
    if let Some(m) = &split {
        stored = motu_compile::stored_stream_split(&s.view(), m.cap_instances).expect("split");
        if let Some(st) = &stored {
            motu_pack::write_stream_split(
                &mut writer,
                &motu_pack::StreamSplitTables {
                    tlases: &st.tlases,
                    blases: &st.blases,
                    pis: &st.pis,
                    instance_source: &st.instance_source,
                    extra_instances: &st.extra_instances,
                },
            )
            .expect("split sections");
        }
    }
    let meta = motu_pack::PackageMeta {
        schema: motu_pack::SCHEMA.into(),
        levels: "ml".into(),
        root_tlas: s.root,
        elements: s
            .names
            .iter()
            .map(|n| motu_pack::ElementMeta {
                name: n.clone(),
                ..Default::default()
            })
            .collect(),
        stream_split: split.map(|m| motu_pack::StreamSplitMeta {
            tlases_split: stored.as_ref().map_or(0, |s| s.tlases_split),
            pieces: stored.as_ref().map_or(0, |s| s.pieces),
            ..m
        }),
        ..Default::default()
    };
    if let Some(bytes) = blas_counts {
        writer
            .add_section(motu_pack::SECTION_BLAS_COUNTS, "blas_counts", 1, bytes)
            .expect("counts section");
    }
    motu_pack::write_hierarchy(&mut writer, &s.view(), &meta).expect("sections");
    writer.finish().expect("finish");
    stored
}

/// JSON of a report without how it was made (`sources`, `timings_ms`).
fn numbers_json(r: &Report) -> serde_json::Value {
    let mut v = serde_json::to_value(r).expect("json");
    let o = v.as_object_mut().expect("object");
    assert!(o.remove("sources").is_some() && o.remove("timings_ms").is_some());
    v
}

/// A package that stored its BLAS counts (as `motu import` does) reports exactly what a
/// report counting every instance itself says, over scenes of shared, nested, split and
/// heavily instanced placements, and says which source it used; a table of another hierarchy
/// or a damaged one is not used (counted again, same numbers).
#[test]
fn stored_blas_counts_change_no_number() {
    let dir = tempfile::tempdir().expect("tmp");
    let scenes = [
        ("forest", forest(), None),
        ("three", three_levels(), None),
        ("buddha", buddha_like(), None),
        // Split sections stored for a cap of 3: the package's recorded cap, which its streamed
        // renders and reports split at (the view alone splits at the default cap, so this
        // scene's reports are compared with one another, not with the view's).
        (
            "split",
            forest(),
            Some(motu_pack::StreamSplitMeta {
                cap_instances: 3,
                ..Default::default()
            }),
        ),
    ];
    let table_of = |o: &Scene| {
        motu_compile::blas_counts::encode_section(
            &o.view(),
            &motu_compile::blas_counts::BlasCounts::of(&o.view()),
        )
    };
    for (name, mut s, split) in scenes {
        // Another scene's table (another instance count).
        let other_bytes = table_of(&if name == "buddha" {
            forest()
        } else {
            buddha_like()
        });
        let view = s.view();
        let counts = motu_compile::blas_counts::BlasCounts::of(&view);
        let bytes = motu_compile::blas_counts::encode_section(&view, &counts);
        // Fewer entries than instances wherever a TLAS repeats a BLAS.
        assert!(counts.entries.len() <= view.instances.len());
        let mut reports = Vec::new();
        for (tag, section) in [
            ("stored", Some(&bytes[..])),
            ("absent", None),
            ("foreign", Some(&other_bytes[..])),
            ("cut", Some(&bytes[..bytes.len() - 8])),
        ] {
            let path = dir.path().join(format!("{name}-{tag}.motu"));
            write_package_with(&mut s, &path, split.clone(), section);
            let pkg = motu_pack::ScenePackage::open(&path).expect("open");
            let r = build_report(&pkg, &lavapipe(), Some(1 << 20)).expect("report");
            let want = if tag == "stored" {
                "package"
            } else {
                "computed"
            };
            assert_eq!(r.provenance.sources.blas_counts, want, "{name} {tag}");
            reports.push(r);
        }
        let mut from_view = s.report(&lavapipe(), Some(1 << 20));
        assert_eq!(from_view.provenance.sources.blas_counts, "computed");
        if split.is_some() {
            assert_eq!(
                reports[0]
                    .streaming
                    .stream_split
                    .as_ref()
                    .map(|s| s.cap_instances),
                Some(3)
            );
            from_view = reports[1].clone();
        }
        for r in &reports {
            from_view.package = r.package.clone();
            assert_eq!(numbers_json(r), numbers_json(&from_view), "{name}");
            assert_eq!(*r, from_view, "{name}");
        }
        if name == "buddha" {
            // 25,251 instances, two entries: the walk is over entries.
            assert_eq!(counts.entries.len(), 2);
            assert_eq!(reports[0].flattened_instances, 25_251);
        }
        // No TLAS over the default cap; the package's recorded cap of 3 splits its stored ones.
        let want = if split.is_some() { "package" } else { "none" };
        assert_eq!(reports[0].provenance.sources.stream_split, want, "{name}");
    }
}

/// `build_report` on a real package (written with motu-pack, without a stored stream split,
/// as packages were before it was stored) equals the report of its tables.
#[test]
fn build_report_reads_a_package() {
    let mut s = forest();
    let dir = tempfile::tempdir().expect("tmp");
    let path = dir.path().join("forest.motu");
    write_package(&mut s, &path, None);
    let pkg = motu_pack::ScenePackage::open(&path).expect("open");
    let from_pkg = build_report(&pkg, &lavapipe(), Some(1 << 20)).expect("report");
    let mut from_view = s.report(&lavapipe(), Some(1 << 20));
    from_view.package = pkg.path().to_string();
    assert_eq!(from_pkg, from_view);
    assert_eq!(from_pkg.elements[0].name, "trees");
}

/// A package's stored stream split reads back as the split a reader would make (sections
/// round trip, every table equal), one for another cap is not used, and the report from a
/// package that stored its split equals the report that splits itself.
#[test]
fn a_stored_stream_split_reads_back_and_changes_no_number() {
    let mut s = forest();
    let dir = tempfile::tempdir().expect("tmp");
    let cap = 3;
    let path = dir.path().join("split.motu");
    let meta = motu_pack::StreamSplitMeta {
        cap_instances: cap,
        ..Default::default()
    };
    let written = write_package(&mut s, &path, Some(meta)).expect("a TLAS over the cap");
    let pkg = motu_pack::ScenePackage::open(&path).expect("open");
    let view = pkg.view().expect("view");
    assert!(pkg.stored_stream_split(cap + 1).expect("read").is_none());
    let t = pkg
        .stored_stream_split(cap)
        .expect("read")
        .expect("for this cap")
        .expect("a split");
    assert_eq!(t.instance_source, &written.instance_source[..]);
    let back = motu_compile::StreamSplit::from_stored(&view, &written).expect("rebuilt");
    let made = motu_compile::split_for_streaming(&view, cap)
        .expect("split")
        .expect("over the cap");
    let (a, b) = (made.view(&view), back.view(&view));
    assert_eq!(
        (a.tlases, a.instances, a.blases, a.pis),
        (b.tlases, b.instances, b.blases, b.pis)
    );
    assert_eq!(made.counts(), back.counts());
    // The renderer's entry point reads the stored split for the package's own view, and
    // splits afresh for any other (here the compiled scene's tables in memory): both equal.
    for v in [view, s.view()] {
        let r = motu_render::package_stream_split(&pkg, &v, cap)
            .expect("split")
            .expect("over the cap");
        let c = r.view(&v);
        assert_eq!(
            (a.tlases, a.instances, a.blases, a.pis),
            (c.tlases, c.instances, c.blases, c.pis)
        );
    }

    // The streamer's own cap: stored as "nothing over it", read without splitting.
    let path = dir.path().join("default.motu");
    let meta = motu_pack::StreamSplitMeta {
        cap_instances: motu_render::STREAM_SPLIT_INSTANCES,
        ..Default::default()
    };
    assert!(write_package(&mut s, &path, Some(meta)).is_none());
    let pkg = motu_pack::ScenePackage::open(&path).expect("open");
    assert!(matches!(
        pkg.stored_stream_split(motu_render::STREAM_SPLIT_INSTANCES),
        Ok(Some(None))
    ));
    let from_pkg = build_report(&pkg, &lavapipe(), Some(1 << 20)).expect("report");
    let mut from_view = s.report(&lavapipe(), Some(1 << 20));
    from_view.package = pkg.path().to_string();
    assert_eq!(from_pkg, from_view);
}

mod props {
    use super::*;
    use proptest::prelude::*;

    /// A random scene: `elements` elements, each placing some prototypes (TLASes of leaf BLAS
    /// instances) through PIs; prototypes are drawn from a common pool, so some are shared.
    fn random_scene(elements: u32, picks: &[(u8, u8, u8)]) -> Scene {
        let names: Vec<String> = (0..elements).map(|i| format!("e{i}")).collect();
        let refs: Vec<&str> = names.iter().map(|s| s.as_str()).collect();
        let mut s = Scene::new(&refs);
        let pool: Vec<u32> = (0..6u32)
            .map(|k| {
                let m = s.mesh(10 + 37 * k);
                let b = s.tri_blas(&[m]);
                s.tlas(&vec![(b, NONE_U32); 1 + k as usize])
            })
            .collect();
        let mut root = Vec::new();
        for (i, &(el, proto, copies)) in picks.iter().enumerate() {
            let el = u32::from(el) % elements;
            let t = pool[proto as usize % pool.len()];
            let pi = s.pi_blas(&vec![t; 1 + copies as usize % 7]);
            root.push((pi, el));
            if i % 4 == 0 {
                let m = s.mesh(5 + i as u32);
                let b = s.tri_blas(&[m]);
                root.push((b, el));
            }
        }
        s.tlas(&root);
        s
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

        /// Rows add up to the whole; a suggestion never exceeds the budget and costs exactly
        /// what the subset scene costs.
        #[test]
        fn suggestions_fit_and_rows_add_up(
            elements in 1u32..6,
            picks in proptest::collection::vec((any::<u8>(), any::<u8>(), any::<u8>()), 1..12),
            budget_frac in 0.05f64..1.2,
        ) {
            let s = random_scene(elements, &picks);
            let full = s.report(&lavapipe(), None);
            let image = (full.streaming.floor.width, full.streaming.floor.height);
            prop_assert_eq!(
                Cost::sum(full.elements.iter().map(|e| &e.ml)).rendered_at(image),
                full.total()
            );
            // A fraction of the structures, beside the render's own overhead.
            let t = full.total();
            let budget = t.render_overhead_bytes
                + ((t.peak_bytes - t.render_overhead_bytes) as f64 * budget_frac) as u64;
            let r = s.report(&lavapipe(), Some(budget));
            let b = r.budget.expect("budget");
            if let Some(sg) = b.suggestion {
                prop_assert!(sg.cost.peak_bytes <= budget);
                let ids: Vec<u32> = sg.elements.iter().map(|n| n[1..].parse().expect("id")).collect();
                let sub = s.subset(&ids).report(&lavapipe(), None).total();
                // The subset scene's structures; its tables plus what `--subset` uploads whole.
                prop_assert_eq!(sg.cost.table_bytes, sub.table_bytes + super::whole_tables(&s));
                prop_assert_eq!(
                    sg.cost.resident_bytes - sg.cost.table_bytes,
                    sub.resident_bytes - sub.table_bytes
                );
                let sub_tris = s.subset(&ids).report(&lavapipe(), None).instanced_triangles;
                prop_assert_eq!(sub_tris, sg.instanced_triangles);
            } else {
                prop_assert!(b.elements.iter().all(|e| !e.fits));
            }
            prop_assert_eq!(b.scene_fits, full.total().peak_bytes <= budget);
        }
    }
}

/// The report's JSON as `motu report --json` writes it (keys in its order), each phase's time
/// at 0 (the phases stay: which ran, in what order, is compared too) and the package path
/// made relative.
fn snapshot_json(r: &Report) -> String {
    let mut r = r.clone();
    r.package = "<package>".into();
    r.provenance.timings_ms = r.provenance.timings_ms.zeroed();
    serde_json::to_string_pretty(&r).expect("json")
}

/// `motu report --json`'s bytes stay what they were (but its phases' milliseconds) over
/// scenes of shared, nested, split and heavily instanced placements, from tables and from
/// packages that stored their split (cap 3) or none: the snapshot `report/snapshot.txt` was
/// written by the report before it was split into phases (`report/build.rs`). A deliberate
/// change rewrites it with `MOTU_UPDATE_SNAPSHOTS=1`.
#[test]
fn report_json_matches_its_snapshot() {
    let dir = tempfile::tempdir().expect("tmp");
    let h200 = ModelSizes::new(&NVIDIA_H200);
    let mut text = String::new();
    let mut add = |name: &str, r: &Report| {
        text += &format!("{name}\n{}\n", snapshot_json(r));
    };
    add("forest", &forest().report(&lavapipe(), Some(1 << 20)));
    add("three_levels", &three_levels().report(&lavapipe(), None));
    add("buddha_like", &buddha_like().report(&h200, Some(64 << 20)));
    for (name, cap) in [("forest_package", None), ("forest_split_package", Some(3))] {
        let mut s = forest();
        let path = dir.path().join(format!("{name}.motu"));
        let meta = cap.map(|cap_instances| motu_pack::StreamSplitMeta {
            cap_instances,
            ..Default::default()
        });
        write_package(&mut s, &path, meta);
        let pkg = motu_pack::ScenePackage::open(&path).expect("open");
        add(
            name,
            &build_report(&pkg, &lavapipe(), Some(1 << 20)).expect("report"),
        );
    }
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src/report/snapshot.txt");
    if std::env::var_os("MOTU_UPDATE_SNAPSHOTS").is_some() {
        std::fs::write(&path, &text).expect("writing the snapshot");
    }
    let want = std::fs::read_to_string(&path).expect("reading the snapshot");
    assert!(
        text == want,
        "the report's JSON changed (MOTU_UPDATE_SNAPSHOTS=1 rewrites {}):\n{}",
        path.display(),
        first_difference(&want, &text)
    );
}

/// The first line where `a` and `b` differ, with its number.
fn first_difference(a: &str, b: &str) -> String {
    let (mut la, mut lb) = (a.lines(), b.lines());
    for n in 1.. {
        match (la.next(), lb.next()) {
            (None, None) => break,
            (x, y) if x != y => return format!("line {n}: {x:?} against {y:?}"),
            _ => {}
        }
    }
    "no line differs".into()
}
