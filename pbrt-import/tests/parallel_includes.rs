//! `ParseOptions::parallel_includes`: the event stream must equal the sequential parse's.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use pbrt_import::{
    parse_file, CameraEvent, Error, FileEvent, InstanceEvent, LightEvent, Material, ObjectEvent,
    ParseOptions, ParseStats, SceneSink, ShapeEvent, SinkError, Warning,
};

/// Every event, in arrival order, as text (geometry included).
#[derive(Default)]
struct Log(Vec<String>);

impl SceneSink for Log {
    fn file_enter(&mut self, e: &FileEvent<'_>) -> Result<(), SinkError> {
        self.0.push(format!("enter {e:?}"));
        Ok(())
    }
    fn file_exit(&mut self, e: &FileEvent<'_>) -> Result<(), SinkError> {
        self.0.push(format!("exit {e:?}"));
        Ok(())
    }
    fn material(&mut self, m: &Arc<Material>) -> Result<(), SinkError> {
        self.0.push(format!("material {m:?}"));
        Ok(())
    }
    fn shape(&mut self, s: ShapeEvent) -> Result<(), SinkError> {
        let mut line = String::from("shape ");
        let _ = write!(line, "{s:?}");
        self.0.push(line);
        Ok(())
    }
    fn object_begin(&mut self, e: &ObjectEvent<'_>) -> Result<(), SinkError> {
        self.0.push(format!("begin {e:?}"));
        Ok(())
    }
    fn object_end(&mut self, e: &ObjectEvent<'_>) -> Result<(), SinkError> {
        self.0.push(format!("end {e:?}"));
        Ok(())
    }
    fn object_instance(&mut self, e: &InstanceEvent<'_>) -> Result<(), SinkError> {
        self.0.push(format!("instance {e:?}"));
        Ok(())
    }
    fn camera(&mut self, e: &CameraEvent<'_>) -> Result<(), SinkError> {
        self.0.push(format!("camera {e:?}"));
        Ok(())
    }
    fn light(&mut self, e: &LightEvent) -> Result<(), SinkError> {
        self.0.push(format!("light {e:?}"));
        Ok(())
    }
    fn warning(&mut self, w: &Warning) {
        self.0.push(format!("warning {w:?}"));
    }
}

type Outcome = (Log, Result<ParseStats, String>);

/// Parse on a 3-thread pool (the parallel path needs more than one thread), with
/// `parallel_includes` on (files cut into pieces of a few lines) or off.
fn run(path: &Path, base: &ParseOptions, parallel: bool) -> Outcome {
    let opts = ParseOptions {
        parallel_includes: parallel,
        parallel_chunk_bytes: 100,
        ..base.clone()
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(3)
        .build()
        .unwrap();
    pool.install(|| {
        let mut log = Log::default();
        let r = parse_file(path, &opts, &mut log).map_err(|e: Error| e.to_string());
        (log, r)
    })
}

/// Parallel and sequential agree on events, stats (but the parallel-file count) and errors.
/// Returns the parallel stats (or error text).
fn assert_same(path: &Path, base: &ParseOptions) -> Result<ParseStats, String> {
    let (seq_log, seq) = run(path, base, false);
    let (par_log, par) = run(path, base, true);
    // The calling thread outside the pool (waits on a condition variable, not `yield_now`).
    let mut global_log = Log::default();
    let opts = ParseOptions {
        parallel_includes: true,
        ..base.clone()
    };
    let global = parse_file(path, &opts, &mut global_log).map_err(|e| e.to_string());
    if let (Ok(g), Ok(p)) = (&global, &par) {
        // Whole files (one piece each) qualify at least as often as cut ones.
        assert!(rayon::current_num_threads() < 2 || g.parallel_files >= p.parallel_files);
    }
    assert_eq!(global_log.0, par_log.0, "{}", path.display());
    assert_eq!(
        global.as_ref().err(),
        par.as_ref().err(),
        "{}",
        path.display()
    );
    assert_eq!(seq_log.0.len(), par_log.0.len(), "{}", path.display());
    for (i, (a, b)) in seq_log.0.iter().zip(&par_log.0).enumerate() {
        assert_eq!(a, b, "event {i} of {}", path.display());
    }
    match (&seq, &par) {
        (Ok(s), Ok(p)) => {
            assert_eq!(s.parallel_files, 0);
            let mut p2 = p.clone();
            p2.parallel_files = 0;
            p2.parallel_window_peak_bytes = 0;
            assert_eq!(*s, p2);
        }
        (Err(s), Err(p)) => assert_eq!(s, p),
        _ => panic!("{}: sequential {seq:?} vs parallel {par:?}", path.display()),
    }
    par
}

fn scene(rel: &str) -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/scenes")
        .join(rel);
    if p.exists() {
        Some(p)
    } else {
        eprintln!("SKIPPED: scene {} not present", p.display());
        None
    }
}

#[test]
fn real_scenes_parse_the_same() {
    let strict = ParseOptions::default();
    let lenient = ParseOptions {
        allow_missing: true,
        ..ParseOptions::default()
    };
    for (rel, opts) in [
        ("buddha-fractal/buddha-fractal.pbrt", &strict),
        ("bmw-m6/bmw-m6.pbrt", &strict),
        ("ecosys/ecosys.pbrt", &lenient),
        ("ecosys/ecosys.pbrt", &strict),
        ("kroken-v4/camera-1.pbrt", &lenient),
    ] {
        if let Some(path) = scene(rel) {
            let _ = assert_same(&path, opts);
        }
    }
}

fn matrix(i: usize) -> String {
    let (x, y, z) = (i as f32 * 1.5, (i % 7) as f32 - 3.25, (i % 3) as f32 * 0.1);
    format!("[ 0.5 0 0 0  0 0.5 0 0  0 0 0.5 0  {x} {y} {z} 1 ]")
}

/// A placement file of the island kind: one-line blocks of a transform and an instance.
fn placement(names: &[&str], start: usize, count: usize) -> String {
    let mut s = String::new();
    for i in start..start + count {
        let name = names[i % names.len()];
        let _ = writeln!(
            s,
            "AttributeBegin Transform {} ObjectInstance \"{name}\" AttributeEnd",
            matrix(i)
        );
    }
    s
}

/// A small island-like scene: an entry file including elements, each defining objects and
/// including runs of placement files, with non-neutral and odd files mixed in.
fn write_island(dir: &Path, v4: bool) {
    let mut entry = String::from(
        "LookAt 0 10 -10  0 0 0  0 1 0\nCamera \"perspective\" \"float fov\" 40\n\
         Film \"image\" \"integer xresolution\" 64 \"integer yresolution\" 32\nWorldBegin\n",
    );
    let inc = if v4 { "Import" } else { "Include" };
    for e in 0..3 {
        let elem = format!("isElem{e}");
        std::fs::create_dir_all(dir.join(&elem)).unwrap();
        // pbrt-v4 forbids redefining an object name: one set per element.
        let owned: Vec<String> = ["leafA", "leafB", "rock"]
            .iter()
            .map(|n| format!("{elem}_{n}"))
            .collect();
        let names: Vec<&str> = owned.iter().map(String::as_str).collect();
        let _ = writeln!(entry, "Include \"{elem}/{elem}.pbrt\"");
        let mut ef = String::new();
        for (k, n) in names.iter().enumerate() {
            let _ = writeln!(
                ef,
                "ObjectBegin \"{n}\"\nShape \"trianglemesh\" \"integer indices\" [0 1 2] \
                 \"point P\" [0 0 {k} 1 0 0 0 1 0]\nObjectEnd"
            );
        }
        ef.push_str("AttributeBegin\nMaterial \"matte\" \"rgb Kd\" [0.2 0.6 0.3]\n");
        for f in 0..9 {
            let file = format!("{elem}_xgLeaf{f}.pbrt");
            let body = match f {
                // Not neutral: a top-level material change that leaks to later files.
                8 => format!(
                    "Material \"matte\" \"rgb Kd\" [0.9 0.1 0.1]\n{}",
                    placement(&names, 100, 5)
                ),
                // Neutral with shapes: a mesh, a quadric, a skipped mesh (bad index),
                // a warning (normal count) and nested transforms.
                4 => format!(
                    "{}TransformBegin Translate 1 2 3 AttributeBegin ReverseOrientation \
                     Rotate 30 0 1 0\nShape \"sphere\" \"float radius\" 0.5\nAttributeEnd\n\
                     Shape \"trianglemesh\" \"integer indices\" [0 1 2 2 1 3] \
                     \"point P\" [0 0 0 1 0 0 0 1 0 1 1 0] \"float alpha\" 0.5\n\
                     Shape \"trianglemesh\" \"integer indices\" [0 1 7] \"point P\" [0 0 0 1 0 0 0 1 0]\n\
                     Shape \"trianglemesh\" \"integer indices\" [0 1 2] \"point P\" [0 0 0 1 0 0 0 1 0] \
                     \"normal N\" [0 0 1]\nTransformEnd\n",
                    placement(&names, 200, 4)
                ),
                // A missing file inside a placement run.
                5 => continue,
                // Needs the main thread (plymesh with a missing file).
                6 => format!(
                    "AttributeBegin Shape \"plymesh\" \"string filename\" \"nope_{elem}.ply\" AttributeEnd\n{}",
                    placement(&names, 300, 3)
                ),
                _ => placement(&names, f * 1000 + e * 10, 40 + f * 7),
            };
            std::fs::write(dir.join(&elem).join(&file), body).unwrap();
        }
        for f in 0..9 {
            let _ = writeln!(ef, "{inc} \"{elem}_xgLeaf{f}.pbrt\"");
        }
        // An instance-only run outside the attribute block, after a comment.
        ef.push_str("AttributeEnd\n# more\n");
        for f in [0, 1, 2] {
            let _ = writeln!(ef, "Include \"{elem}_xgLeaf{f}.pbrt\"");
        }
        std::fs::write(dir.join(&elem).join(format!("{elem}.pbrt")), ef).unwrap();
    }
    if v4 {
        entry.insert_str(0, "ColorSpace \"srgb\"\n");
    }
    std::fs::write(dir.join("island.pbrt"), entry).unwrap();
}

/// On a pool of many threads the window of a parallel run stops at its cap (32 pieces),
/// plus the one file that crosses the line: with 64 threads the old per-thread window
/// (4 pieces each, 256 here) would hold 8× as much of this run.
#[test]
fn the_window_stays_bounded_for_many_threads() {
    let dir = tempfile::tempdir().unwrap();
    let names = ["leaf"];
    let mut entry = String::from(
        "WorldBegin\nObjectBegin \"leaf\"\nShape \"trianglemesh\" \"integer indices\" \
         [0 1 2] \"point P\" [0 0 0 1 0 0 0 1 0]\nObjectEnd\n",
    );
    let (mut largest, mut total) = (0u64, 0u64);
    for f in 0..120 {
        let body = placement(&names, f * 100, 10 + f % 13);
        largest = largest.max(body.len() as u64);
        total += body.len() as u64;
        std::fs::write(dir.path().join(format!("p{f}.pbrt")), body).unwrap();
        let _ = writeln!(entry, "Include \"p{f}.pbrt\"");
    }
    std::fs::write(dir.path().join("scene.pbrt"), entry).unwrap();
    let piece_bytes = 100;
    let opts = ParseOptions {
        parallel_chunk_bytes: piece_bytes,
        ..ParseOptions::default()
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(64)
        .build()
        .unwrap();
    let stats = pool
        .install(|| parse_file(&dir.path().join("scene.pbrt"), &opts, &mut Log::default()))
        .unwrap();
    assert_eq!(stats.parallel_files, 120);
    let cap = 32 * piece_bytes as u64;
    // The run needs more than the cap, so the cap is what stops it.
    assert!(total > 64 * 4 * piece_bytes as u64, "{total}");
    let peak = stats.parallel_window_peak_bytes;
    assert!(peak >= cap, "window peaked at {peak} under its cap {cap}");
    assert!(
        peak < cap + largest,
        "window peaked at {peak}: over the cap {cap} plus one file ({largest})"
    );
}

#[test]
fn generated_island_parses_the_same_and_in_parallel() {
    for v4 in [false, true] {
        let dir = tempfile::tempdir().unwrap();
        write_island(dir.path(), v4);
        let path = dir.path().join("island.pbrt");
        let lenient = ParseOptions {
            allow_missing: true,
            ..ParseOptions::default()
        };
        let stats = assert_same(&path, &lenient).unwrap();
        // Per element: 6 neutral placement files in the run and 3 after it, but the one
        // with a multi-line block is cut inside the block and falls back as a whole.
        assert_eq!(stats.parallel_files, 3 * 8, "v4 = {v4}");
        assert_eq!(stats.missing.len(), 6);
        assert!(stats.skipped_shapes >= 3);
        // Strict: the same missing-file error either way.
        let err = assert_same(&path, &ParseOptions::default()).unwrap_err();
        assert!(err.contains("isElem0_xgLeaf5.pbrt"), "{err}");
        // Sharing repeated includes composes with the parallel path.
        let shared = ParseOptions {
            share_repeated_includes: true,
            ..lenient.clone()
        };
        assert_same(&path, &shared).unwrap();
    }
}

#[test]
fn errors_in_parallel_files_keep_their_positions() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("a.pbrt"), placement(&["obj"], 0, 3)).unwrap();
    // Unknown object (pbrt-v3): found at replay time, line 2.
    std::fs::write(
        d.join("b.pbrt"),
        format!(
            "{}{}",
            placement(&["obj"], 0, 1),
            placement(&["nobody"], 1, 1)
        ),
    )
    .unwrap();
    // Malformed transform: the worker gives up, the sequential parse reports it.
    std::fs::write(
        d.join("c.pbrt"),
        "AttributeBegin Transform [1 2 3] ObjectInstance \"obj\" AttributeEnd\n",
    )
    .unwrap();
    let head = "WorldBegin\nObjectBegin \"obj\" Shape \"sphere\" ObjectEnd\n";
    for (file, want) in [("b.pbrt", "b.pbrt:2:"), ("c.pbrt", "c.pbrt:1:")] {
        let entry = d.join(format!("entry_{file}"));
        std::fs::write(
            &entry,
            format!("{head}Include \"a.pbrt\"\nInclude \"{file}\"\nInclude \"a.pbrt\"\n"),
        )
        .unwrap();
        let err = assert_same(&entry, &ParseOptions::default()).unwrap_err();
        assert!(err.contains(want), "{err} lacks {want}");
    }
}

#[test]
fn v4_forward_references_resolve_the_same() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("p1.pbrt"), placement(&["late", "early"], 0, 4)).unwrap();
    std::fs::write(d.join("p2.pbrt"), placement(&["late", "never"], 0, 2)).unwrap();
    let head =
        "ColorSpace \"srgb\"\nWorldBegin\nObjectBegin \"early\" Shape \"sphere\" ObjectEnd\n";
    let tail = "ObjectBegin \"late\" Shape \"disk\" ObjectEnd\n";
    let ok = d.join("ok.pbrt");
    std::fs::write(
        &ok,
        format!("{head}Import \"p1.pbrt\"\nImport \"p1.pbrt\"\n{tail}"),
    )
    .unwrap();
    let stats = assert_same(&ok, &ParseOptions::default()).unwrap();
    assert_eq!((stats.parallel_files, stats.instances), (2, 8));
    let bad = d.join("bad.pbrt");
    std::fs::write(
        &bad,
        format!("{head}Import \"p1.pbrt\"\nImport \"p2.pbrt\"\n{tail}"),
    )
    .unwrap();
    let err = assert_same(&bad, &ParseOptions::default()).unwrap_err();
    assert!(err.contains("p2.pbrt:2:"), "{err}");
}
