//! Built structures that survive eviction and the process (issue 45 items 2 and 3): the host
//! cache restores what a camera path evicted and needs again, a warm cache directory spares a
//! second process every build it cached, bad entries and unwritable directories are warnings,
//! and every image equals the path with everything resident.

use motu_tests::{
    gen_island_with, gpu_available, json_u64, motu_ok, render_env, report_peak_and_floor, s,
};
use std::path::{Path, PathBuf};

/// The default island imported without its stored proxy boxes and clusters (`--no-proxy-boxes
/// --no-proxy-clusters`, as an older package: the structure cache then keeps the boxes and
/// clusters the start makes), its 64×36 peak, and the
/// reference path (room for everything, no cache).
struct Fixture {
    dir: tempfile::TempDir,
    pkg: PathBuf,
    peak: u64,
    reference: PathBuf,
}

impl Fixture {
    fn new() -> Option<Fixture> {
        if !gpu_available() {
            return None;
        }
        let dir = tempfile::tempdir().unwrap();
        let pkg = gen_island_with(
            dir.path(),
            None,
            &["--no-proxy-boxes", "--no-proxy-clusters"],
        );
        let (peak, _floor) = report_peak_and_floor(&pkg, "64", "36");
        let f = Fixture {
            reference: dir.path().join("reference.aov"),
            dir,
            pkg,
            peak,
        };
        let budget = (f.peak * 2).to_string();
        path(
            &f,
            "reference",
            "query",
            &budget,
            &["--host-cache", "0", "--no-as-cache"],
            &[],
        );
        Some(f)
    }

    /// The full build's still frame (the default camera, 64×36) as AOV file `name`.aov.
    fn still_reference(&self, name: &str) -> PathBuf {
        let aov = self.dir.path().join(format!("{name}.aov"));
        let args = ["--width", "64", "--height", "36", "--frames", "1"];
        render_env(&self.pkg, "pipeline", &aov, &args, &[]);
        aov
    }

    fn same_as_reference(&self, aov: &Path) {
        motu_ok(&["compare", s(&self.reference), s(aov), "--max-mismatch", "0"]);
    }
}

/// A streamed render of `frames` frames at 64×36 under `budget`.
fn streamed_args<'a>(frames: &'a str, budget: &'a str) -> Vec<&'a str> {
    vec![
        "--width",
        "64",
        "--height",
        "36",
        "--frames",
        frames,
        "--stream",
        "--vram-budget",
        budget,
    ]
}

/// The default 8-frame streamed path at 64×36 (`--stats` beside the AOV).
fn path(
    f: &Fixture,
    name: &str,
    backend: &str,
    budget: &str,
    extra: &[&str],
    env: &[(&str, &str)],
) -> (serde_json::Value, PathBuf) {
    let aov = f.dir.path().join(format!("{name}.aov"));
    let mut args = streamed_args("8", budget);
    // The streamer and its cache, also at budgets that hold the whole scene.
    args.push("--stream-always");
    args.extend(extra);
    (render_env(&f.pkg, backend, &aov, &args, env), aov)
}

fn totals(st: &serde_json::Value) -> &serde_json::Value {
    &st["stream"]["totals"]
}

fn warnings(st: &serde_json::Value, reason: &str) -> u64 {
    json_u64(&st["stream"]["cache"]["disk"]["warnings"][reason])
}

#[test]
fn a_path_that_returns_restores_from_the_host_cache() {
    let Some(f) = Fixture::new() else { return };
    // A quarter of the peak: the path evicts structures its later frames need again.
    let budget = (f.peak / 4).to_string();
    let (off, off_aov) = path(
        &f,
        "host-off",
        "query",
        &budget,
        &["--host-cache", "0", "--no-as-cache"],
        &[],
    );
    // Every BLAS stored (`always`): the host tier's restores themselves. Whether they pay is
    // the store rule's call (`measured`, below).
    let (on, on_aov) = path(
        &f,
        "host-on",
        "query",
        &budget,
        &["--no-as-cache", "--stream-host-cache-policy", "always"],
        &[],
    );
    let (t0, t1) = (totals(&off), totals(&on));
    eprintln!("without: {t0}\nwith: {t1}");
    assert!(
        json_u64(&t0["rebuilt_blases"]) > 0,
        "the path rebuilds without a cache: {t0}"
    );
    assert_eq!(json_u64(&t0["restored_blases"]), 0, "{t0}");
    assert!(
        json_u64(&t1["restored_blases"]) > 0,
        "restores from the host cache: {t1}"
    );
    let host_hits = json_u64(&on["stream"]["cache"]["host_hits"]);
    assert!(host_hits > 0, "{}", on["stream"]["cache"]);
    assert!(
        json_u64(&t1["rebuilt_bytes"]) < json_u64(&t0["rebuilt_bytes"]),
        "fewer rebuilt bytes with the cache: {} against {}",
        t1["rebuilt_bytes"],
        t0["rebuilt_bytes"]
    );
    assert!(json_u64(&t1["restored_bytes"]) > 0 && t1["restore_gb_per_s"].as_f64().unwrap() > 0.0);
    // Unified memory: serialised as built (the readback at eviction would take the room the
    // eviction makes), no clones.
    assert_eq!(t1["host_cache_mode"], "serialize", "{t1}");
    assert_eq!(json_u64(&t1["cloned_blases"]), 0, "{t1}");
    assert_eq!(json_u64(&t1["host_cache_skipped_stores"]), 0, "{t1}");
    assert_eq!(t1["store_policy"]["policy"], "always", "{t1}");
    f.same_as_reference(&off_aov);
    f.same_as_reference(&on_aov);

    // The default rule (`measured`): each BLAS built is stored or skipped by this process's
    // own rates (lavapipe under load: restores and stores each cost about what a rebuild
    // does, so it stores few); its counts add up, and the image is the full build's.
    let (m, m_aov) = path(
        &f,
        "host-measured",
        "query",
        &budget,
        &["--no-as-cache"],
        &[],
    );
    let tm = totals(&m);
    let p = &tm["store_policy"];
    eprintln!("measured: {tm}");
    assert_eq!(p["policy"], "measured", "{p}");
    // Every build and restore is a sample or a count of the rule.
    assert!(json_u64(&p["build_batches"]) >= 3, "{p}");
    assert_eq!(
        json_u64(&p["built_blases"]) + json_u64(&p["returns"]),
        json_u64(&tm["blas_built"]) + json_u64(&tm["restored_blases"]),
        "{tm}"
    );
    assert_eq!(
        json_u64(&p["returns"]),
        json_u64(&tm["rebuilt_blases"]) + json_u64(&tm["restored_blases"]),
        "{tm}"
    );
    // Each BLAS built was stored or skipped by the rule, at most once (one a cache held
    // already, its restore refused for room, is neither).
    let decided = json_u64(&tm["cache_stored"]) + json_u64(&tm["host_cache_skipped_stores"]);
    assert!(
        decided > 0 && decided <= json_u64(&tm["blas_built"]),
        "{tm}"
    );
    f.same_as_reference(&m_aov);

    // Host memory apart from the budget (a discrete GPU): an evicted BLAS is cloned into host
    // memory by the device and cloned back when it returns; nothing is serialised while the
    // frames render. lavapipe's host-visible memory is its device memory (unified), where a
    // clone would take the room its eviction made, so the mode that clones is never chosen
    // there by itself (`--stream-host-cache auto` serialises); MOTU_SIMULATE_DISCRETE_MEMORY=1
    // counts host memory apart from the budget as a discrete GPU does, and lavapipe runs the
    // device-side clone copies themselves (`CLONE` mode) like any driver: the clones, the
    // restores from them and the entries persisted from them are all checked here.
    let discrete = [("MOTU_SIMULATE_DISCRETE_MEMORY", "1")];
    let cache = f.dir.path().join("cache-clones");
    let clone_flags = [
        "--as-cache",
        s(&cache),
        "--stream-host-cache",
        "clone",
        "--stream-host-cache-policy",
        "always",
    ];
    let (cl, cl_aov) = path(
        &f,
        "host-clone",
        "pipeline",
        &budget,
        &clone_flags,
        &discrete,
    );
    let tc = totals(&cl);
    eprintln!("clones: {tc}");
    assert_eq!(tc["host_cache_mode"], "clone", "{tc}");
    assert!(
        json_u64(&tc["cloned_blases"]) > 0,
        "evicted BLASes cloned: {tc}"
    );
    assert!(
        json_u64(&tc["restored_from_clone"]) > 0,
        "returns cloned back: {tc}"
    );
    assert!(
        json_u64(&tc["host_clone_bytes"]) > 0 && json_u64(&tc["cloned_bytes"]) > 0,
        "{tc}"
    );
    assert!(
        json_u64(&tc["rebuilt_bytes"]) < json_u64(&t0["rebuilt_bytes"]),
        "fewer rebuilt bytes with clones: {} against {}",
        tc["rebuilt_bytes"],
        t0["rebuilt_bytes"]
    );
    // Nothing serialised while the frames rendered: every stored structure was written after
    // them (`persist_cache`), some of them from clones of evicted BLASes.
    let persisted = json_u64(&tc["persisted_blases"]);
    assert!(persisted > 0, "{tc}");
    assert_eq!(json_u64(&tc["cache_stored"]), persisted, "{tc}");
    assert!(
        json_u64(&tc["persisted_from_clone"]) > 0,
        "entries written from host clones: {tc}"
    );
    assert!(persisted <= json_u64(&tc["blas_built"]), "{tc}");
    f.same_as_reference(&cl_aov);
    // A second process on that directory restores every structure instead of building it,
    // those persisted from clones too; its image is the full build's.
    let (warm, warm_aov) = path(
        &f,
        "host-clone-warm",
        "pipeline",
        &budget,
        &clone_flags,
        &discrete,
    );
    let tw = totals(&warm);
    eprintln!("clones, warm: {tw}");
    assert_eq!(json_u64(&tw["blas_built"]), 0, "nothing rebuilt: {tw}");
    assert!(
        json_u64(&warm["stream"]["cache"]["disk_hits"]) >= persisted,
        "every persisted entry read back: {} against {persisted}",
        warm["stream"]["cache"]
    );
    f.same_as_reference(&warm_aov);
}

#[test]
fn a_second_process_with_a_warm_cache_rebuilds_nothing_it_cached() {
    let Some(f) = Fixture::new() else { return };
    let budget = (f.peak * 2).to_string();
    for backend in ["query", "pipeline"] {
        if backend == "query" && !motu_tests::has_ray_query() {
            eprintln!("SKIPPED the query backend: the device has no ray queries");
            continue;
        }
        let cache = f.dir.path().join(format!("cache-{backend}"));
        let dir = ["--as-cache", s(&cache)];
        // The pipeline backend's runs count host memory apart from the budget, as a discrete
        // GPU does: the store and restore batches then reuse kept transfer buffers.
        let discrete: &[(&str, &str)] = if backend == "pipeline" {
            &[("MOTU_SIMULATE_DISCRETE_MEMORY", "1")]
        } else {
            &[]
        };
        // The pipeline backend's runs keep clones (written to the directory after the frames).
        let mode = if discrete.is_empty() {
            "serialize"
        } else {
            "clone"
        };
        // Every cached BLAS restored (`always`): the cache itself, whatever this device's rates
        // say (lavapipe's restores cost about what its builds do: the restore rule may build).
        let flags = [
            dir[0],
            dir[1],
            "--stream-host-cache",
            mode,
            "--stream-host-cache-policy",
            "always",
        ];
        let (cold, cold_aov) = path(
            &f,
            &format!("cold-{backend}"),
            backend,
            &budget,
            &flags,
            discrete,
        );
        let stored = json_u64(&totals(&cold)["cache_stored"]);
        let built = json_u64(&totals(&cold)["blas_built"]);
        assert!(
            stored > 0 && stored == built,
            "every build is cached: {}",
            totals(&cold)
        );
        // With host memory apart the structures are kept as clones while the path renders and
        // serialised into the directory after its frames; else as they are built.
        let persisted = json_u64(&totals(&cold)["persisted_blases"]);
        if discrete.is_empty() {
            assert_eq!(persisted, 0, "{}", totals(&cold));
        } else {
            assert_eq!(totals(&cold)["host_cache_mode"], "clone");
            assert_eq!(
                persisted,
                stored,
                "written after the frames: {}",
                totals(&cold)
            );
        }
        let (warm, warm_aov) = path(
            &f,
            &format!("warm-{backend}"),
            backend,
            &budget,
            &flags,
            discrete,
        );
        let t = totals(&warm);
        for (run, st) in [("cold", &cold), ("warm", &warm)] {
            let tt = totals(st);
            let (batches, allocs) = (
                json_u64(&tt["transfer_batches"]),
                json_u64(&tt["transfer_allocations"]),
            );
            eprintln!("{backend} {run}: {allocs} transfer buffers for {batches} batches");
            assert!(batches > 0, "{run}: {tt}");
            if discrete.is_empty() {
                assert_eq!(
                    allocs, batches,
                    "{run}: one buffer a batch on unified memory"
                );
            } else {
                // Two directions, each grown at most from 16 to 256 MiB (5 sizes).
                assert!(
                    allocs <= 10 && (batches < 4 || allocs < batches),
                    "{run}: kept buffers ({allocs} allocations for {batches} batches)"
                );
            }
        }
        assert_eq!(json_u64(&t["blas_built"]), 0, "nothing rebuilt: {t}");
        assert_eq!(json_u64(&t["restored_blases"]), stored, "{t}");
        // The start's proxy boxes: made from the meshes and kept, then read back.
        assert_eq!(totals(&cold)["proxy_boxes_cached"], false);
        assert_eq!(t["proxy_boxes_cached"], true, "{t}");
        assert_eq!(totals(&cold)["proxy_boxes_source"], "computed");
        assert_eq!(t["proxy_boxes_source"], "cache", "{t}");
        assert_eq!(proxy_table_entries(&cache).len(), 1);
        // The proxy clusters too.
        assert_eq!(cold["stream"]["startup"]["clusters_cached"], false);
        assert_eq!(warm["stream"]["startup"]["clusters_cached"], true);
        assert_eq!(cold["stream"]["startup"]["clusters_source"], "computed");
        assert_eq!(warm["stream"]["startup"]["clusters_source"], "cache");
        assert_eq!(
            json_u64(&warm["stream"]["cache"]["disk_hits"]),
            stored + 2,
            "every structure, the proxy-box table and the stream plan"
        );
        f.same_as_reference(&cold_aov);
        f.same_as_reference(&warm_aov);
    }
}

/// One still frame (`--frames 1`) streamed at 64×36 under `budget` with a cache directory,
/// host memory counted apart from the budget as on a discrete GPU (`--stats` beside the AOV).
fn still(f: &Fixture, name: &str, budget: &str, extra: &[&str]) -> (serde_json::Value, PathBuf) {
    let aov = f.dir.path().join(format!("{name}.aov"));
    let mut args = streamed_args("1", budget);
    args.extend(extra);
    let discrete = [("MOTU_SIMULATE_DISCRETE_MEMORY", "1")];
    (render_env(&f.pkg, "pipeline", &aov, &args, &discrete), aov)
}

fn frame0(st: &serde_json::Value) -> &serde_json::Value {
    &st["stream"]["frames"][0]
}

/// Entry files' names (their keys) of a cache directory's serialised structures.
fn entry_names(cache: &Path) -> Vec<String> {
    let mut out: Vec<String> = entries(cache)
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    out.sort();
    out
}

#[test]
fn a_still_frame_stores_only_evicted_blases_in_frame_and_the_rest_after_its_image() {
    let Some(f) = Fixture::new() else { return };
    // A sixth of the peak: the frame evicts structures (some return in later passes). (At a
    // quarter its working set fits since pass 1 builds only what pixels wait for first.)
    let budget = (f.peak / 6).to_string();
    let reference = f.still_reference("still-reference");
    let same = |aov: &Path| {
        motu_ok(&["compare", s(&reference), s(aov), "--max-mismatch", "0"]);
    };
    // As built, inside the frame (`--stream-host-cache serialize`, the behaviour before).
    let built_dir = f.dir.path().join("cache-as-built");
    // Fixed rates (every cached BLAS restored, as the deferred run's `always`): the frame's
    // returns then do not follow this machine's timing, so the two runs build the same.
    let as_built = [
        "--as-cache",
        s(&built_dir),
        "--stream-host-cache",
        "serialize",
        motu_tests::PINNED_RATES[0],
        motu_tests::PINNED_RATES[1],
    ];
    let (a, a_aov) = still(&f, "still-as-built", &budget, &as_built);
    // The default: at eviction, and the rest after the image.
    let deferred_dir = f.dir.path().join("cache-deferred");
    // `always`: every cached BLAS restored by the warm process below, whatever the rates say.
    let deferred = [
        "--as-cache",
        s(&deferred_dir),
        "--stream-host-cache-policy",
        "always",
    ];
    let (d, d_aov) = still(&f, "still-deferred", &budget, &deferred);
    let (fa, fd, td) = (frame0(&a), frame0(&d), totals(&d));
    eprintln!("as built: {fa}\ndeferred: {fd}\ntotals: {td}");
    assert_eq!(totals(&a)["host_cache_mode"], "serialize");
    assert_eq!(td["host_cache_mode"], "deferred", "{td}");
    assert!(json_u64(&fd["evicted"]) > 0, "the frame evicts: {fd}");
    // In the frame only evicted BLASes were serialised; those resident at its end after it.
    let in_frame = json_u64(&fd["cache_stored"]);
    assert!(in_frame <= json_u64(&fd["evicted"]), "{fd}");
    assert!(
        in_frame < json_u64(&fa["cache_stored"]),
        "fewer stores in the frame: {in_frame} against {}",
        fa["cache_stored"]
    );
    assert!(
        json_u64(&fd["cache_stored_bytes"]) < json_u64(&fa["cache_stored_bytes"]),
        "{fd}"
    );
    let persisted = json_u64(&td["persisted_blases"]);
    assert!(
        persisted > 0 && json_u64(&td["persisted_bytes"]) > 0,
        "{td}"
    );
    assert_eq!(json_u64(&td["cache_stored"]), in_frame + persisted, "{td}");
    assert_eq!(json_u64(&totals(&a)["persisted_blases"]), 0);
    // The next process is as warm: the same entries, one per BLAS built.
    let (na, nd) = (entry_names(&built_dir), entry_names(&deferred_dir));
    assert_eq!(json_u64(&fd["cache_skipped"]), 0, "{fd}");
    assert_eq!(
        nd.len() as u64,
        json_u64(&td["store_policy"]["built_blases"]),
        "one entry per BLAS built: {td}"
    );
    assert_eq!(na, nd, "the same entries as stored as built");
    // A second process rebuilds nothing and restores every entry.
    let (w, w_aov) = still(&f, "still-deferred-warm", &budget, &deferred);
    let tw = totals(&w);
    eprintln!("warm: {tw}");
    assert_eq!(json_u64(&tw["blas_built"]), 0, "nothing rebuilt: {tw}");
    assert!(
        json_u64(&w["stream"]["cache"]["disk_hits"]) >= nd.len() as u64,
        "{}",
        w["stream"]["cache"]
    );
    assert_eq!(json_u64(&tw["persisted_blases"]), 0, "{tw}");
    // Staged transfers: by default only where the room above the floor leaves a 32nd for the
    // staging buffer and it is at least 1 MiB, which this scene's budget does not; forced here
    // (`MOTU_AS_TRANSFER=staged`), they move the same structures through the device-local
    // staging buffer and a second process restores them all through it.
    for st in [td, tw] {
        assert_eq!(json_u64(&st["transfer_staged_runs"]), 0, "{st}");
    }
    let staged_dir = f.dir.path().join("cache-staged");
    let staged_flags = [
        "--as-cache",
        s(&staged_dir),
        "--stream-host-cache-policy",
        "always",
    ];
    // Half the peak: at a quarter the staging buffer yields to structures in the frame (the
    // floor test below).
    let half = (f.peak / 2).to_string();
    let staged = |name: &str| {
        let aov = f.dir.path().join(format!("{name}.aov"));
        let mut args = streamed_args("1", &half);
        args.extend(staged_flags);
        let env = [
            ("MOTU_SIMULATE_DISCRETE_MEMORY", "1"),
            ("MOTU_AS_TRANSFER", "staged"),
        ];
        (render_env(&f.pkg, "pipeline", &aov, &args, &env), aov)
    };
    let (sc, sc_aov) = staged("still-staged");
    let (sw, sw_aov) = staged("still-staged-warm");
    let (tsc, tsw) = (totals(&sc), totals(&sw));
    eprintln!("staged: {tsc}\nstaged warm: {tsw}");
    for st in [tsc, tsw] {
        assert!(json_u64(&st["transfer_staged_runs"]) > 0, "{st}");
    }
    // One entry per BLAS built (the staging buffer's room may change which are built).
    assert_eq!(
        entry_names(&staged_dir).len() as u64,
        json_u64(&tsc["store_policy"]["built_blases"]),
        "{tsc}"
    );
    assert_eq!(json_u64(&tsw["blas_built"]), 0, "nothing rebuilt: {tsw}");
    assert!(json_u64(&tsw["restored_blases"]) > 0, "{tsw}");
    for aov in [&a_aov, &d_aov, &w_aov, &sc_aov, &sw_aov] {
        same(aov);
    }
}

/// The cache's entry files of serialised structures, sorted (not the proxy-box table and the
/// stream plan the streamer keeps beside them).
fn entries(cache: &Path) -> Vec<PathBuf> {
    let mut tables = proxy_table_entries(cache);
    tables.extend(entries_starting(cache, b"motu stream plan"));
    all_entries(cache)
        .into_iter()
        .filter(|p| !tables.contains(p))
        .collect()
}

/// The entry files holding a proxy-box table (their blob starts with its magic).
fn proxy_table_entries(cache: &Path) -> Vec<PathBuf> {
    entries_starting(cache, b"motu proxy-box table")
}

/// The entry files whose blob starts with `magic`.
fn entries_starting(cache: &Path, magic: &[u8]) -> Vec<PathBuf> {
    let mut disk = motu_ascache::DiskCache::open(cache, Default::default());
    all_entries(cache)
        .into_iter()
        .filter(|p| {
            let key = p.file_stem().and_then(|s| s.to_str()).unwrap();
            let key = motu_ascache::CacheKey::from_hex(key).unwrap();
            disk.get(&key, &motu_ascache::AnyDevice)
                .is_some_and(|b| b.starts_with(magic))
        })
        .collect()
}

/// The cache's entry files (`v1/ab/<hex key>.as`), sorted.
fn all_entries(cache: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![cache.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "as") {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

#[test]
fn corrupt_truncated_and_foreign_entries_are_rebuilt_with_a_warning() {
    let Some(f) = Fixture::new() else { return };
    let budget = (f.peak * 2).to_string();
    let cache = f.dir.path().join("cache");
    // `always`: every good entry restored, whatever this device's rates say.
    let dir = [
        "--host-cache",
        "0",
        "--as-cache",
        s(&cache),
        "--stream-host-cache-policy",
        "always",
    ];
    let (cold, _) = path(&f, "cold", "pipeline", &budget, &dir, &[]);
    let stored = json_u64(&totals(&cold)["cache_stored"]);
    let files = entries(&cache);
    assert_eq!(files.len() as u64, stored, "{files:?}");
    assert!(files.len() >= 3);
    // One byte flipped in the middle of an entry.
    let mut bytes = std::fs::read(&files[0]).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x5a;
    std::fs::write(&files[0], &bytes).unwrap();
    // An entry cut short.
    let bytes = std::fs::read(&files[1]).unwrap();
    std::fs::write(&files[1], &bytes[..bytes.len() / 3]).unwrap();
    // A whole, well-formed entry written for another driver: its serialised header's driver
    // UUID differs, so the device refuses it as incompatible.
    let key_hex = files[2].file_stem().unwrap().to_str().unwrap();
    let key = motu_ascache::CacheKey::from_hex(key_hex).unwrap();
    let mut disk = motu_ascache::DiskCache::open(&cache, Default::default());
    let mut blob = disk
        .get(&key, &motu_ascache::AnyDevice)
        .expect("entry readable")
        .to_vec();
    for b in &mut blob[..16] {
        *b ^= 0xff;
    }
    assert!(disk.put(&key, &blob));
    drop(disk);

    let out = motu_tests::motu(&[
        "render",
        s(&f.pkg),
        "-o",
        s(&f.dir.path().join("bad.png")),
        "--backend",
        "pipeline",
        "--aov",
        s(&f.dir.path().join("bad.aov")),
        "--stats",
        s(&f.dir.path().join("bad.json")),
        "--width",
        "64",
        "--height",
        "36",
        "--frames",
        "8",
        "--stream",
        "--stream-always",
        "--vram-budget",
        &budget,
        "--host-cache",
        "0",
        "--as-cache",
        s(&cache),
        "--stream-host-cache-policy",
        "always",
        // As the cold run (`path` pins it): bounce rays would need structures it never built.
        "--bounces",
        "0",
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    let st: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(f.dir.path().join("bad.json")).unwrap())
            .unwrap();
    for reason in ["corrupt", "truncated", "incompatible"] {
        assert_eq!(
            warnings(&st, reason),
            1,
            "{reason}: {}",
            st["stream"]["cache"]
        );
        assert!(
            err.contains(reason),
            "the {reason} entry is warned about: {err}"
        );
    }
    let t = totals(&st);
    assert_eq!(
        json_u64(&t["blas_built"]),
        3,
        "exactly the bad entries rebuilt: {t}"
    );
    assert_eq!(json_u64(&t["restored_blases"]), stored - 3, "{t}");
    f.same_as_reference(&f.dir.path().join("bad.aov"));
}

#[test]
fn a_read_only_or_full_cache_directory_renders_with_a_warning() {
    let Some(f) = Fixture::new() else { return };
    let budget = (f.peak * 2).to_string();
    // Read-only: as root chmod does not stop writes, so a directory under sysfs (which refuses
    // every new file) stands for one; as another user a 0555 directory does.
    let ro = if is_root() {
        PathBuf::from("/sys/motu-as-cache-test")
    } else {
        let d = f.dir.path().join("read-only");
        std::fs::create_dir(&d).unwrap();
        std::fs::set_permissions(&d, std::os::unix::fs::PermissionsExt::from_mode(0o555)).unwrap();
        d
    };
    let (st, aov) = path(
        &f,
        "read-only",
        "pipeline",
        &budget,
        &["--as-cache", s(&ro)],
        &[],
    );
    let c = &st["stream"]["cache"];
    assert!(warnings(&st, "read_only") + warnings(&st, "io") >= 1, "{c}");
    assert_eq!(c["disk"]["writable"], false, "{c}");
    f.same_as_reference(&aov);
    // Full: every write fails as on a full disk.
    let full = f.dir.path().join("full");
    let (st, aov) = path(
        &f,
        "full",
        "pipeline",
        &budget,
        &["--as-cache", s(&full)],
        &[("MOTU_AS_CACHE_SIMULATE", "full")],
    );
    assert!(warnings(&st, "full") >= 1, "{}", st["stream"]["cache"]);
    assert!(entries(&full).is_empty());
    f.same_as_reference(&aov);
}

fn is_root() -> bool {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("Uid:"))
                .map(|l| l.split_whitespace().nth(1) == Some("0"))
        })
        .unwrap_or(false)
}

/// A forced staging buffer (`MOTU_AS_TRANSFER=staged`, host memory apart) at the streaming
/// floor, where the frame needs all of the room: it yields to structures (freed, counted) and
/// the frame is complete and equals the full build.
#[test]
fn a_staging_buffer_at_the_floor_yields_to_structures() {
    let Some(f) = Fixture::new() else { return };
    let (_peak, floor) = report_peak_and_floor(&f.pkg, "64", "36");
    let reference = f.still_reference("floor-reference");
    let aov = f.dir.path().join("floor-staged.aov");
    let budget = floor.to_string();
    let mut args = streamed_args("1", &budget);
    args.push("--no-as-cache");
    let env = [
        ("MOTU_SIMULATE_DISCRETE_MEMORY", "1"),
        ("MOTU_AS_TRANSFER", "staged"),
    ];
    let st = render_env(&f.pkg, "pipeline", &aov, &args, &env);
    let (fr, t) = (frame0(&st), totals(&st));
    eprintln!("{fr}");
    assert_eq!(fr["complete"], true, "{fr}");
    assert_eq!(json_u64(&t["transfer_staging_released"]), 1, "{t}");
    motu_ok(&["compare", s(&reference), s(&aov), "--max-mismatch", "0"]);
}

/// The rates file a process wrote in `cache` (`rates-v1/<device>.txt`, one device here) and the
/// device identity in it.
fn rates_file(cache: &Path) -> (PathBuf, String) {
    let dir = cache.join(motu_ascache::rates::RATES_DIR);
    let files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(files.len(), 1, "{files:?}");
    let text = std::fs::read_to_string(&files[0]).unwrap();
    let device = text
        .lines()
        .find_map(|l| l.strip_prefix("device "))
        .expect("a device line")
        .to_string();
    (files[0].clone(), device)
}

fn policy(st: &serde_json::Value) -> &serde_json::Value {
    &totals(st)["store_policy"]
}

/// Issue 45.3: restores and directory writes follow this device's measured rates, kept in the
/// cache directory for the next process. A cold process records its rates; a warm one starts
/// from them (lavapipe: restores beat CPU builds, so it restores everything); rates that say
/// building is faster (written into the file as another device's measurements would be)
/// decline every restore and every write; a corrupt file is a warning and the priors. Every
/// image is the full build's.
#[test]
fn measured_rates_decide_restores_and_writes_across_processes() {
    let Some(f) = Fixture::new() else { return };
    let budget = (f.peak * 2).to_string();
    let reference = f.still_reference("rates-reference");
    let same = |aov: &Path| {
        motu_ok(&["compare", s(&reference), s(aov), "--max-mismatch", "0"]);
    };
    let cache = f.dir.path().join("cache-rates");
    let flags = ["--stream-always", "--as-cache", s(&cache)];
    let (cold, cold_aov) = still(&f, "rates-cold", &budget, &flags);
    let (tc, pc) = (totals(&cold), policy(&cold));
    eprintln!("cold: {tc}");
    assert_eq!(pc["rates_file"], "missing", "{pc}");
    assert_eq!(pc["rates_saved"], true, "{pc}");
    let written = json_u64(&tc["cache_stored"]);
    assert!(
        written > 0 && json_u64(&tc["disk_store_skipped"]) == 0,
        "{tc}"
    );
    let (file, device) = rates_file(&cache);
    let saved =
        motu_ascache::rates::decode_rates(&std::fs::read_to_string(&file).unwrap(), &device)
            .expect("a valid rates file");
    assert!(saved.build.is_some(), "the cold process built: {saved:?}");

    // Warm: the build rate from the file, restores unknown, so the first ones are restored and
    // measured; then each is restored or declined by the rates (on lavapipe restores cost
    // about what builds do: either); a declined one is built, nothing else is.
    let (warm, warm_aov) = still(&f, "rates-warm", &budget, &flags);
    let (tw, pw) = (totals(&warm), policy(&warm));
    eprintln!("warm: {tw}");
    assert_eq!(pw["rates_file"], "loaded", "{pw}");
    let declined_warm = json_u64(&tw["disk_restore_declined"]);
    assert!(json_u64(&tw["restored_blases"]) > 0, "{tw}");
    assert_eq!(
        json_u64(&tw["restored_blases"]) + declined_warm,
        written,
        "{tw}"
    );
    assert_eq!(json_u64(&tw["blas_built"]), declined_warm, "{tw}");

    // Rates saying a restore is far slower than a build (a device with fast builds and a slow
    // disk): nothing is read, everything built.
    let slow = motu_ascache::Rate {
        batches: 10,
        per_blas_ms: 1e3,
        gb_per_s: 1e-6,
    };
    let forged = motu_ascache::DeviceRates {
        restore: Some(slow),
        disk_read: Some(slow),
        ..saved
    };
    std::fs::write(&file, motu_ascache::rates::encode_rates(&device, &forged)).unwrap();
    let (declined, declined_aov) = still(&f, "rates-declined", &budget, &flags);
    let (td, pd) = (totals(&declined), policy(&declined));
    eprintln!("declined: {td}");
    assert_eq!(pd["rates_file"], "loaded", "{pd}");
    assert_eq!(json_u64(&td["restored_blases"]), 0, "{td}");
    assert_eq!(json_u64(&td["disk_restore_declined"]), written, "{td}");
    let warm_disk_hits = json_u64(&warm["stream"]["cache"]["disk_hits"]);
    assert!(json_u64(&td["disk_restore_declined_bytes"]) > 0, "{td}");
    assert_eq!(json_u64(&td["blas_built"]), written, "{td}");
    // Declined entries are never read (the start's tables still are).
    assert_eq!(
        json_u64(&declined["stream"]["cache"]["disk_hits"]) + written,
        warm_disk_hits + declined_warm,
        "{}",
        declined["stream"]["cache"]
    );

    // A cold process in a fresh directory that has those rates writes no structure there.
    let fresh = f.dir.path().join("cache-rates-fresh");
    std::fs::create_dir_all(fresh.join(motu_ascache::rates::RATES_DIR)).unwrap();
    let fresh_file = fresh
        .join(motu_ascache::rates::RATES_DIR)
        .join(file.file_name().unwrap());
    std::fs::write(
        &fresh_file,
        motu_ascache::rates::encode_rates(&device, &forged),
    )
    .unwrap();
    let fresh_flags = ["--stream-always", "--as-cache", s(&fresh)];
    let (skip, skip_aov) = still(&f, "rates-skip", &budget, &fresh_flags);
    let ts = totals(&skip);
    eprintln!("cold with slow restores: {ts}");
    assert_eq!(
        json_u64(&ts["disk_store_skipped"]),
        json_u64(&ts["blas_built"]),
        "{ts}"
    );
    assert!(json_u64(&ts["disk_store_skipped_bytes"]) > 0, "{ts}");
    assert!(entries(&fresh).is_empty(), "no structure written");

    // A corrupt rates file: a warning, the priors (unknown: restore), and rewritten.
    let mut bytes = std::fs::read(&file).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x01;
    std::fs::write(&file, &bytes).unwrap();
    let aov = f.dir.path().join("rates-corrupt.aov");
    let mut args = streamed_args("1", &budget);
    args.extend(flags);
    let st = render_env(
        &f.pkg,
        "pipeline",
        &aov,
        &args,
        &[("MOTU_SIMULATE_DISCRETE_MEMORY", "1")],
    );
    let (tb, pb) = (totals(&st), policy(&st));
    eprintln!("corrupt rates: {tb}");
    assert_eq!(pb["rates_file"], "corrupt", "{pb}");
    // Unknown rates: restored (and measured) until this process's fits decide.
    assert!(json_u64(&tb["restored_blases"]) > 0, "{tb}");
    assert_eq!(
        json_u64(&tb["restored_blases"]) + json_u64(&tb["disk_restore_declined"]),
        written,
        "{tb}"
    );
    assert_eq!(pb["rates_saved"], true, "{pb}");
    motu_ascache::rates::decode_rates(&std::fs::read_to_string(&file).unwrap(), &device)
        .expect("rewritten whole");
    for aov in [&cold_aov, &warm_aov, &declined_aov, &skip_aov, &aov] {
        same(aov);
    }
}

/// Fixed rates (`--stream-rates`, notes/rates52.md): the restore and store rules decide from
/// them alone, never from this machine's timing, so one command run twice gives the same
/// counts frame by frame while the rule restores some cached structures and declines others.
/// A cold process whose rates say restores pay writes what it builds; two warm processes over
/// that directory, whose rates add a fixed cost to each restore that only structures above the
/// entries' mean size repay, restore those from the directory and build the rest, count for
/// count the same along a path that evicts and returns. No process reads or writes a rates
/// file; every image is the full build's.
#[test]
fn fixed_rates_decide_the_same_on_every_run() {
    let Some(f) = Fixture::new() else { return };
    let budget = (f.peak / 4).to_string();
    let cache = f.dir.path().join("cache-fixed");
    let run = |name: &str, rates: &str| {
        let extra = ["--as-cache", s(&cache), "--stream-rates", rates];
        path(&f, name, "query", &budget, &extra, &[])
    };
    let no_rates_file = |st: &serde_json::Value| {
        assert_eq!(policy(st)["rates_file"], "fixed", "{}", policy(st));
        assert_eq!(policy(st)["rates_saved"], false, "{}", policy(st));
        assert!(!cache.join(motu_ascache::rates::RATES_DIR).exists());
    };
    let (cold, cold_aov) = run("fixed-cold", motu_tests::PINNED_RATES[1]);
    let tc = totals(&cold);
    eprintln!("cold: {tc}");
    no_rates_file(&cold);
    assert_eq!(json_u64(&tc["disk_store_skipped"]), 0, "{tc}");
    assert_eq!(json_u64(&tc["host_restore_declined"]), 0, "{tc}");
    assert!(
        json_u64(&tc["restored_blases"]) > 0,
        "the path returns: {tc}"
    );
    let sizes: Vec<u64> = entries(&cache)
        .iter()
        .map(|p| std::fs::metadata(p).unwrap().len())
        .collect();
    assert!(sizes.len() >= 3, "{sizes:?}");
    // Builds at 1 GB/s, restores and reads free but for a fixed cost per structure: a cached
    // structure of S bytes is restored when S ≥ the mean entry's bytes.
    let mean = sizes.iter().sum::<u64>() / sizes.len() as u64;
    let split = format!(
        "build=1,restore=inf+{},disk_read=inf,store=inf",
        mean as f64 / 1e6
    );
    let (w1, w1_aov) = run("fixed-warm-1", &split);
    let (w2, w2_aov) = run("fixed-warm-2", &split);
    let t1 = totals(&w1);
    eprintln!("warm (split at {mean} B): {t1}");
    for st in [&w1, &w2] {
        no_rates_file(st);
    }
    assert!(
        motu_tests::stream_total(&w1, "restored_from_disk") > 0,
        "{t1}"
    );
    assert!(json_u64(&t1["disk_restore_declined"]) > 0, "{t1}");
    assert!(json_u64(&t1["blas_built"]) > 0, "{t1}");
    let (c1, c2) = (
        motu_tests::stream_frame_counts(&w1),
        motu_tests::stream_frame_counts(&w2),
    );
    assert!(c1.len() > 8 * 50, "counts of every frame: {}", c1.len());
    let differ: Vec<_> = c1.iter().zip(&c2).filter(|(a, b)| a != b).collect();
    assert!(
        differ.is_empty() && c1.len() == c2.len(),
        "two runs with fixed rates differ: {differ:?}"
    );
    for aov in [&cold_aov, &w1_aov, &w2_aov] {
        f.same_as_reference(aov);
    }
}
