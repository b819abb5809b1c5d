//! The partitioner (issue 14, item 1): geometry compiles to triangle BLASes of bounded size,
//! and hit records still name the source mesh and primitive, so a partitioned package renders
//! the same AOV as an unpartitioned one on every backend, for `ml`, `sl`, `auto`, LOD chains
//! and `--subset`.

use motu_tests::{gpu_available, has_ray_query, import, motu_json, motu_ok, render, s};
use std::path::{Path, PathBuf};

/// A bound no mesh reaches: the unpartitioned compile (one BLAS per prototype, as before).
const UNPARTITIONED: &str = "4294967295";

fn info(pkg: &Path) -> serde_json::Value {
    motu_json(&["info", s(pkg), "--json"])
}

/// Backends to check: the CPU oracle, and both GPU backends where a device exists (CI has
/// lavapipe and sets MOTU_REQUIRE_GPU, so they are not skipped there).
fn backends() -> Vec<&'static str> {
    let mut b = vec!["cpu"];
    if gpu_available() {
        b.push("pipeline");
        if has_ray_query() {
            b.push("query");
        }
    }
    b
}

/// Renders both packages with every backend; each backend's AOVs must match with 0 mismatches
/// (and, in the ids view, their PNGs byte for byte: the colour hashes the source primitive).
fn assert_same_renders(dir: &Path, name: &str, partitioned: &Path, whole: &Path, extra: &[&str]) {
    for b in backends() {
        let aov = |tag: &str| -> PathBuf { dir.join(format!("{name}-{tag}-{b}.aov")) };
        let stats = render(partitioned, b, &aov("p"), extra);
        render(whole, b, &aov("u"), extra);
        if b != "cpu" {
            assert_report_agrees(partitioned, &stats);
        }
        let (hits, pixels) = aov_hits(&aov("p"));
        assert!(
            4 * hits > pixels,
            "{name} {b}: only {hits} of {pixels} pixels hit"
        );
        let out = motu_ok(&["compare", s(&aov("p")), s(&aov("u")), "--max-mismatch", "0"]);
        assert!(out.contains("(0 of "), "{name} {b}: {out}");
        if extra.contains(&"ids") {
            let png = |tag: &str| std::fs::read(aov(tag).with_extension("png")).unwrap();
            assert!(png("p") == png("u"), "{name} {b}: ids images differ");
        }
        eprintln!("{name} {b}: partitioned vs whole: {out}");
    }
}

/// `motu report` reads the partitioned package: its AS and geometry bytes for the compiled
/// hierarchy agree with what the GPU built (within 2%: allocation alignment).
fn assert_report_agrees(pkg: &Path, stats: &serde_json::Value) {
    let r = motu_json(&["report", s(pkg), "--json"]);
    let cost = &r["variants"][0]["cost"];
    let model_as = cost["blas_bytes"].as_u64().unwrap() + cost["tlas_bytes"].as_u64().unwrap();
    let model_geo = cost["geometry_bytes"].as_u64().unwrap();
    let gpu_as = stats["as_bytes"].as_u64().unwrap();
    let gpu_geo = stats["resources"]["alloc"]["kinds"]["geometry"]["bytes"]
        .as_u64()
        .unwrap();
    let close = |a: u64, b: u64| (a as f64 - b as f64).abs() <= 0.02 * b as f64;
    assert!(
        close(model_as, gpu_as),
        "AS: report {model_as}, GPU {gpu_as}"
    );
    assert!(
        close(model_geo, gpu_geo),
        "geometry: report {model_geo}, GPU {gpu_geo}"
    );
}

/// (hit pixels, pixels) of an AOV file (FORMAT.md "AOV file format": a 32-byte header, then
/// 16-byte records whose first u32 is the mesh, `0xFFFFFFFF` for a miss).
fn aov_hits(aov: &Path) -> (usize, usize) {
    let bytes = std::fs::read(aov).unwrap();
    let records = bytes[32..].chunks_exact(16);
    let pixels = records.len();
    let hits = records
        .filter(|r| u32::from_le_bytes(r[..4].try_into().unwrap()) != u32::MAX)
        .count();
    (hits, pixels)
}

fn triangles_per_blas(pkg: &Path) -> (u64, u64, u64) {
    let i = info(pkg);
    (
        i["max_triangles_per_blas"].as_u64().unwrap(),
        i["max_blas_triangles"].as_u64().unwrap(),
        i["partitioned_meshes"].as_u64().unwrap(),
    )
}

/// One dense mesh (≈20k triangles) instanced 2×2, partitioned with a small bound for speed, in
/// `ml`, `sl` and `auto`, and with a LOD chain whose levels are partitioned too.
#[test]
fn partitioned_dense_mesh_renders_like_the_whole_one() {
    let dir = tempfile::tempdir().unwrap();
    let gen = dir.path().join("grid");
    motu_ok(&[
        "gen",
        "lod-grid",
        "-o",
        s(&gen),
        "--triangles",
        "20000",
        "--grid",
        "2x2",
    ]);
    let scene = gen.join("scene.pbrt");
    let view = ["--width", "48", "--view", "ids"];
    for levels in ["ml", "sl", "auto"] {
        let p = dir.path().join(format!("{levels}-p.motu"));
        let u = dir.path().join(format!("{levels}-u.motu"));
        import(
            &scene,
            &p,
            &["--levels", levels, "--max-blas-triangles", "2000"],
        );
        import(
            &scene,
            &u,
            &["--levels", levels, "--max-blas-triangles", UNPARTITIONED],
        );
        let (largest, bound, split) = triangles_per_blas(&p);
        assert_eq!(bound, 2000);
        assert!((1000..=2000).contains(&largest), "{levels}: {largest}");
        assert_eq!(split, 1, "{levels}: the dense mesh is split");
        let (whole, _, none) = triangles_per_blas(&u);
        assert!(whole > 15_000 && none == 0, "{levels}: {whole}");
        motu_ok(&["verify", s(&p)]);
        assert_same_renders(dir.path(), levels, &p, &u, &view);
    }
    // LOD chain: every level over the bound is partitioned; hits name the level's primitive.
    let p = dir.path().join("lod-p.motu");
    let u = dir.path().join("lod-u.motu");
    let lod = ["--lod", "3", "--lod-min-triangles", "1000"];
    import(
        &scene,
        &p,
        &[&lod[..], &["--max-blas-triangles", "2000"]].concat(),
    );
    import(
        &scene,
        &u,
        &[&lod[..], &["--max-blas-triangles", UNPARTITIONED]].concat(),
    );
    let (largest, _, split) = triangles_per_blas(&p);
    assert!(largest <= 2000, "{largest}");
    assert!(split >= 2, "levels 0 and 1 are over the bound: {split}");
    assert_same_renders(dir.path(), "lod", &p, &u, &view);
}

/// Defaults only: the default island (no generator flags) has no BLAS above the bound chosen
/// from its size (under 2^16: a small scene), renders like its unpartitioned compile on every
/// backend, and `--subset` partitions the same way; `--max-blas-triangles` overrides the choice.
#[test]
fn default_island_is_partitioned_under_the_default_bound() {
    let dir = tempfile::tempdir().unwrap();
    let gen = dir.path().join("island");
    motu_ok(&["gen", "island", "-o", s(&gen)]);
    let scene = gen.join("scene.pbrt");
    let p = dir.path().join("p.motu");
    let u = dir.path().join("u.motu");
    import(&scene, &p, &[]);
    import(&scene, &u, &["--max-blas-triangles", UNPARTITIONED]);
    let (largest, bound, split) = triangles_per_blas(&p);
    // The automatic bound: a 256th of the island's build in triangles (521k triangles + 2 per
    // instance), at least 4,096.
    assert!(
        (4_096..65_536).contains(&bound),
        "chosen from the scene's size: {bound}"
    );
    assert!(largest <= bound, "{largest} > {bound}");
    assert!(split > 0, "the island's terrain meshes are over the bound");
    let (whole, _, _) = triangles_per_blas(&u);
    assert!(
        whole > 4 * bound,
        "the unpartitioned island has {whole}-triangle BLASes"
    );
    let o = dir.path().join("o.motu");
    import(&scene, &o, &["--max-blas-triangles", "65536"]);
    let (o_largest, o_bound, _) = triangles_per_blas(&o);
    assert_eq!(o_bound, 65_536, "the flag overrides the choice");
    assert!(o_largest > bound && o_largest <= o_bound, "{o_largest}");
    // `motu report` reads the partitioned package: its largest BLAS is the bounded one.
    let rp = motu_json(&["report", s(&p), "--json"]);
    let ru = motu_json(&["report", s(&u), "--json"]);
    let largest_blas = |r: &serde_json::Value| {
        r["streaming"]["largest_blas_compacted_bytes"]
            .as_u64()
            .unwrap()
    };
    assert!(
        largest_blas(&rp) * 4 < largest_blas(&ru),
        "report: {} vs {}",
        largest_blas(&rp),
        largest_blas(&ru)
    );
    assert_same_renders(
        dir.path(),
        "island",
        &p,
        &u,
        &["--width", "64", "--camera", "birdseyeCam"],
    );

    let sp = dir.path().join("sub-p.motu");
    let su = dir.path().join("sub-u.motu");
    import(&scene, &sp, &["--subset", "osOcean,isCoral"]);
    import(
        &scene,
        &su,
        &[
            "--subset",
            "osOcean,isCoral",
            "--max-blas-triangles",
            UNPARTITIONED,
        ],
    );
    let (largest, _, split) = triangles_per_blas(&sp);
    assert!(largest <= bound && split > 0, "{largest} {split}");
    motu_ok(&["verify", s(&sp)]);
    let ids = ["--width", "48", "--view", "ids"];
    let (a, b) = (dir.path().join("sub-p.aov"), dir.path().join("sub-u.aov"));
    render(&sp, "cpu", &a, &ids);
    render(&su, "cpu", &b, &ids);
    let out = motu_ok(&["compare", s(&a), s(&b), "--max-mismatch", "0"]);
    assert!(out.contains("(0 of "), "subset: {out}");
}
