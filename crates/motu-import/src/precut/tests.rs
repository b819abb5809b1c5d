//! Cutting while parsing makes the package the compile-time cut makes: the same tables, the
//! same mesh records (but for where their data lies) and the same cluster data.

use crate::{import, ImportOptions, ImportSummary};
use std::cell::Cell;
use std::fmt::Write as _;
use std::path::Path;

thread_local! {
    /// Overrides `(stored triangles, bound)` at which the automatic bound is taken as known.
    pub(crate) static SETTLES: Cell<Option<(u64, u32)>> = const { Cell::new(None) };
}

/// A `trianglemesh` grid of `n × n` quads (a regular grid: many equal centroid coordinates,
/// where a cut that depended on the order of its input would differ), wavy in z.
fn grid(out: &mut String, n: u32, origin: [f32; 3], shading: bool) {
    let v = |i: u32, j: u32| {
        let (x, y) = (i as f32 / n as f32, j as f32 / n as f32);
        [
            origin[0] + x,
            origin[1] + y,
            origin[2] + 0.05 * (7.0 * x).sin() * (5.0 * y).cos(),
        ]
    };
    out.push_str("Shape \"trianglemesh\" \"point3 P\" [");
    for j in 0..=n {
        for i in 0..=n {
            let p = v(i, j);
            let _ = write!(out, " {} {} {}", p[0], p[1], p[2]);
        }
    }
    out.push_str(" ] \"integer indices\" [");
    for j in 0..n {
        for i in 0..n {
            let a = j * (n + 1) + i;
            let _ = write!(
                out,
                " {a} {} {} {a} {} {}",
                a + 1,
                a + n + 2,
                a + n + 2,
                a + n + 1
            );
        }
    }
    out.push_str(" ]");
    if shading {
        out.push_str(" \"normal N\" [");
        for _ in 0..(n + 1) * (n + 1) {
            out.push_str(" 0 0 1");
        }
        out.push_str(" ] \"point2 uv\" [");
        for j in 0..=n {
            for i in 0..=n {
                let _ = write!(out, " {} {}", i as f32 / n as f32, j as f32 / n as f32);
            }
        }
        out.push_str(" ]");
    }
    out.push('\n');
}

/// Root meshes over and under the bound (one with normals and UVs) and an object with a mesh
/// over it, placed twice.
fn write_scene(dir: &Path) -> std::path::PathBuf {
    let mut s = String::from("Camera \"perspective\" \"float fov\" 45\nWorldBegin\n");
    s.push_str("ObjectBegin \"rock\"\n");
    grid(&mut s, 52, [0.0, 0.0, 0.0], false);
    s.push_str("ObjectEnd\n");
    grid(&mut s, 50, [0.0, 0.0, 5.0], false);
    grid(&mut s, 60, [2.0, 0.0, 5.0], true);
    grid(&mut s, 4, [4.0, 0.0, 5.0], false);
    grid(&mut s, 47, [6.0, 0.0, 5.0], true);
    for x in [0, 3] {
        let _ = writeln!(
            s,
            "AttributeBegin\nTranslate {x} 2 6\nObjectInstance \"rock\"\nAttributeEnd"
        );
    }
    let path = dir.join("scene.pbrt");
    std::fs::write(&path, s).unwrap();
    path
}

fn options(cut: bool, bound: Option<u32>) -> ImportOptions {
    ImportOptions {
        chunk_bytes: 1 << 20,
        max_blas_triangles: bound,
        cut_while_parsing: cut,
        ..Default::default()
    }
}

/// The packages are the same but for where mesh data lies in the chunks.
fn assert_same_package(a: &Path, b: &Path) {
    let pa = motu_pack::ScenePackage::open(a).unwrap();
    let pb = motu_pack::ScenePackage::open(b).unwrap();
    let (va, vb) = (pa.view().unwrap(), pb.view().unwrap());
    assert_eq!(va.root_tlas, vb.root_tlas);
    assert_eq!(va.tlases, vb.tlases);
    assert_eq!(va.instances, vb.instances);
    assert_eq!(va.blases, vb.blases);
    assert_eq!(va.geometries, vb.geometries);
    assert_eq!(va.pis, vb.pis);
    assert_eq!(va.lod_selectors, vb.lod_selectors);
    assert_eq!(va.lod_levels, vb.lod_levels);
    assert_eq!(va.materials, vb.materials);
    assert_eq!(va.meshes.len(), vb.meshes.len());
    let placed = |m: &motu_abi::MeshRecord| motu_abi::MeshRecord {
        chunk: 0,
        positions_offset: 0,
        indices_offset: 0,
        normals_offset: u64::from(m.normals_offset == motu_abi::NONE_U64),
        primitive_map_offset: u64::from(m.primitive_map_offset == motu_abi::NONE_U64),
        uvs_offset: u64::from(m.uvs_offset == motu_abi::NONE_U64),
        ..*m
    };
    for (i, (ma, mb)) in va.meshes.iter().zip(vb.meshes).enumerate() {
        assert_eq!(placed(ma), placed(mb), "mesh record {i}");
        assert_eq!(
            pa.mesh_geometry(i as u32).unwrap(),
            pb.mesh_geometry(i as u32).unwrap(),
            "mesh record {i}'s data"
        );
    }
    let (ma, mb) = (pa.meta(), pb.meta());
    assert_eq!(ma.scene, mb.scene);
    assert_eq!(ma.elements, mb.elements);
    assert_eq!(ma.mesh_names, mb.mesh_names);
    let counts = |c: &serde_json::Value| {
        let mut c = c.clone();
        let o = c.as_object_mut().unwrap();
        o.remove("time_ms");
        o.remove("phases");
        c
    };
    assert_eq!(counts(&ma.compile), counts(&mb.compile));
}

fn run(dir: &Path, name: &str, o: &ImportOptions) -> ImportSummary {
    let out = dir.join(name);
    let s = import(&write_scene(dir), &out, o).unwrap();
    // Neither the spill file nor anything else is left beside the package.
    assert!(!out.with_extension("partition-spill.motu").exists());
    s
}

#[test]
fn a_given_bound_cuts_while_parsing_into_the_compile_time_package() {
    let dir = tempfile::tempdir().unwrap();
    let old = run(dir.path(), "old.motu", &options(false, Some(700)));
    let new = run(dir.path(), "new.motu", &options(true, Some(700)));
    assert_eq!(old.cut_triangles, 0);
    // Every mesh over 700 triangles: 2·52², 2·50², 2·60², 2·47².
    assert_eq!(
        new.cut_triangles,
        2 * (52 * 52 + 50 * 50 + 60 * 60 + 47 * 47)
    );
    assert_eq!((old.meshes, old.blas_count), (new.meshes, new.blas_count));
    assert_same_package(&dir.path().join("old.motu"), &dir.path().join("new.motu"));
}

#[test]
fn the_automatic_bound_cuts_meshes_spilled_before_it_was_known() {
    let dir = tempfile::tempdir().unwrap();
    let old = run(dir.path(), "old.motu", &options(false, None));
    let pkg = motu_pack::ScenePackage::open(&dir.path().join("old.motu")).unwrap();
    let bound = pkg.meta().compile["max_blas_triangles"].as_u64().unwrap() as u32;
    assert_eq!(
        bound,
        motu_compile::MIN_AUTO_MAX_BLAS_TRIANGLES,
        "a small scene"
    );
    drop(pkg);
    // Known at the second root mesh: the object's mesh and the first root mesh, spilled
    // whole before, are cut then (read back from the spill file); the last ones as stored.
    SETTLES.with(|s| s.set(Some((2 * (50 * 50 + 60 * 60), bound))));
    let new = run(dir.path(), "new.motu", &options(true, None));
    SETTLES.with(|s| s.set(None));
    assert_eq!(old.cut_triangles, 0);
    // Over 4,096 triangles: 2·52² (the object), 2·50², 2·60², 2·47².
    assert_eq!(
        new.cut_triangles,
        2 * (52 * 52 + 50 * 50 + 60 * 60 + 47 * 47)
    );
    assert_same_package(&dir.path().join("old.motu"), &dir.path().join("new.motu"));
}

#[test]
fn lod_and_auto_levels_keep_the_compile_time_cut() {
    let dir = tempfile::tempdir().unwrap();
    let o = ImportOptions {
        lod_levels: Some(2),
        ..options(true, Some(700))
    };
    assert_eq!(run(dir.path(), "lod.motu", &o).cut_triangles, 0);
    let o = ImportOptions {
        levels: motu_compile::Levels::Auto,
        levels_text: "auto".into(),
        ..options(true, Some(700))
    };
    assert_eq!(run(dir.path(), "auto.motu", &o).cut_triangles, 0);
}

#[test]
fn cutting_beside_the_parser_makes_the_package_cutting_in_turn_makes() {
    let dir = tempfile::tempdir().unwrap();
    let o = |queue_bytes| ImportOptions {
        cut_queue_bytes: queue_bytes,
        ..options(true, Some(700))
    };
    // 0: each mesh cut before the parser goes on; 1 byte: the cutting thread one mesh behind;
    // the default: every mesh queued until parsing ends.
    let seq = run(dir.path(), "seq.motu", &o(0));
    let one = run(dir.path(), "one.motu", &o(1));
    let all = run(dir.path(), "all.motu", &o(crate::DEFAULT_CUT_QUEUE_BYTES));
    run(dir.path(), "again.motu", &o(crate::DEFAULT_CUT_QUEUE_BYTES));
    for s in [&seq, &one, &all] {
        assert_eq!(s.cut_triangles, 2 * (52 * 52 + 50 * 50 + 60 * 60 + 47 * 47));
    }
    assert_same_package(&dir.path().join("seq.motu"), &dir.path().join("one.motu"));
    assert_same_package(&dir.path().join("seq.motu"), &dir.path().join("all.motu"));
    // Clusters are appended at points that depend only on the meshes: every record in the
    // same place each run (the meta differs only by its timings).
    assert_same_package(&dir.path().join("all.motu"), &dir.path().join("again.motu"));
    let meshes = |n: &str| {
        let p = motu_pack::ScenePackage::open(&dir.path().join(n)).unwrap();
        let m = p.view().unwrap().meshes.to_vec();
        m
    };
    assert_eq!(meshes("all.motu"), meshes("again.motu"));
}
