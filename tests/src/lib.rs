//! Shared helpers for the workspace integration tests: they drive the real `motu` binary on
//! real (`shared/scenes`) and generated scenes.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

/// The `motu` binary of this workspace, brought up to date once per test process.
pub fn motu_bin() -> PathBuf {
    static BIN: OnceLock<PathBuf> = OnceLock::new();
    BIN.get_or_init(|| {
        // target/<profile>/deps/<test-exe> → target/<profile>/motu
        let exe = std::env::current_exe().expect("test executable path");
        let profile_dir = exe
            .parent()
            .and_then(Path::parent)
            .expect("target/<profile>");
        let bin = profile_dir.join("motu");
        // Always (once per test process): a binary left from an older build would test old code.
        // In the tests' own profile (`cargo test --release` runs target/release/motu).
        {
            let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
            let mut args = vec!["build", "-p", "motu-cli"];
            if profile_dir.file_name().is_some_and(|n| n == "release") {
                args.push("--release");
            }
            let status = Command::new(cargo)
                .args(&args)
                .status()
                .expect("running cargo build -p motu-cli");
            assert!(status.success(), "cargo build -p motu-cli failed");
        }
        assert!(bin.exists(), "{} missing after build", bin.display());
        bin
    })
    .clone()
}

/// Runs `motu` with `args`; returns the output whatever the exit status.
pub fn motu(args: &[&str]) -> Output {
    motu_env(args, &[])
}

/// [`motu`] with environment variables set. Unless `env` names `MOTU_AS_CACHE`, each run
/// gets a fresh structure-cache directory of its own (removed after it), so no test's counts
/// depend on what an earlier one left in the user's cache.
pub fn motu_env(args: &[&str], env: &[(&str, &str)]) -> Output {
    let fresh = (!env.iter().any(|(k, _)| *k == "MOTU_AS_CACHE"))
        .then(|| tempfile::tempdir().expect("a temp dir for the structure cache"));
    let mut cmd = Command::new(motu_bin());
    cmd.args(args).envs(env.iter().copied());
    if let Some(d) = &fresh {
        cmd.env("MOTU_AS_CACHE", d.path());
    }
    cmd.output().expect("spawning motu")
}

/// Runs `motu` and asserts success, returning stdout.
pub fn motu_ok(args: &[&str]) -> String {
    motu_ok_env(args, &[])
}

/// [`motu_ok`] with environment variables set.
pub fn motu_ok_env(args: &[&str], env: &[(&str, &str)]) -> String {
    let out = motu_env(args, env);
    assert!(
        out.status.success(),
        "motu {} failed:\nstdout: {}\nstderr: {}",
        args.join(" "),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("utf-8 stdout")
}

/// Runs `motu ... --json` and parses the one object it prints.
pub fn motu_json(args: &[&str]) -> serde_json::Value {
    let out = motu_ok(args);
    serde_json::from_str(&out)
        .unwrap_or_else(|e| panic!("motu {} printed non-JSON ({e}): {out}", args.join(" ")))
}

/// `motu gen island -o DIR/island` (at `scale`; `None`: the generator's default, no other
/// flag) and its default import: `DIR/island.motu`.
pub fn gen_island(dir: &Path, scale: Option<&str>) -> PathBuf {
    gen_island_with(dir, scale, &[])
}

/// The opening of the streaming tests: `None` (the test returns, said loudly by
/// [`gpu_available`]) without a ray-tracing device, else a new temporary directory and
/// [`gen_island`] at `scale` in it. Keep the directory alive while the package is used.
pub fn gpu_island(scale: Option<&str>) -> Option<(tempfile::TempDir, PathBuf)> {
    if !gpu_available() {
        return None;
    }
    let dir = tempfile::tempdir().expect("temporary directory");
    let pkg = gen_island(dir.path(), scale);
    Some((dir, pkg))
}

/// [`gen_island`] imported with `import_extra` flags (`--no-proxy-boxes`, say).
pub fn gen_island_with(dir: &Path, scale: Option<&str>, import_extra: &[&str]) -> PathBuf {
    let gen = dir.join("island");
    let mut args = vec!["gen", "island", "-o", s(&gen)];
    if let Some(sc) = scale {
        args.extend(["--scale", sc]);
    }
    motu_ok(&args);
    let pkg = dir.join("island.motu");
    import(&gen.join("scene.pbrt"), &pkg, import_extra);
    pkg
}

/// `motu gen lod-grid -o DIR/NAME --grid GRID --triangles 20000` imported with `--lod LOD` as
/// `DIR/PKG`: the generated directory and the package.
pub fn gen_lod_grid(
    dir: &Path,
    name: &str,
    grid: &str,
    pkg: &str,
    lod: &str,
) -> (PathBuf, PathBuf) {
    let gen = dir.join(name);
    motu_ok(&[
        "gen",
        "lod-grid",
        "-o",
        s(&gen),
        "--grid",
        grid,
        "--triangles",
        "20000",
    ]);
    let out = dir.join(pkg);
    import(&gen.join("scene.pbrt"), &out, &["--lod", lod]);
    (gen, out)
}

/// `motu gen forest -o DIR/forest FLAGS...` (`--levels`, `--grid`, `--leaves`): the generated
/// scene file.
pub fn gen_forest(dir: &Path, flags: &[&str]) -> PathBuf {
    let gen = dir.join("forest");
    let mut args = vec!["gen", "forest", "-o", s(&gen)];
    args.extend(flags);
    motu_ok(&args);
    gen.join("scene.pbrt")
}

/// The generated island's `shotCam` (DIR/island/cameras/shotCam.pbrt: its `LookAt` and fov)
/// as a camera-path pose, its eye moved `dolly` of the way toward the `LookAt` target (0: the
/// camera itself).
pub fn shot_cam_pose(dir: &Path, dolly: f64) -> serde_json::Value {
    let (cam, nums) = island_camera(dir, "shotCam");
    let fov: f64 = cam
        .split("\"float fov\" [")
        .nth(1)
        .and_then(|r| r.split(']').next())
        .and_then(|v| v.trim().parse().ok())
        .expect("fov");
    let f: Vec<f64> = (0..3).map(|i| nums[3 + i] - nums[i]).collect();
    let len = f.iter().map(|v| v * v).sum::<f64>().sqrt();
    let eye: Vec<f64> = (0..3).map(|i| nums[i] + f[i] * dolly).collect();
    serde_json::json!({
        "eye": eye,
        "forward": f.iter().map(|v| v / len).collect::<Vec<_>>(),
        "up": &nums[6..9],
        "fov_deg": fov,
    })
}

/// The generated island's camera `name` (DIR/island/cameras/NAME.pbrt): its text and the nine
/// numbers of its `LookAt` (eye, target, up).
pub fn island_camera(dir: &Path, name: &str) -> (String, Vec<f64>) {
    let cam = std::fs::read_to_string(dir.join(format!("island/cameras/{name}.pbrt")))
        .unwrap_or_else(|e| panic!("{name}: {e}"));
    let nums = cam
        .split_whitespace()
        .skip_while(|t| *t != "LookAt")
        .skip(1)
        .take(9)
        .map(|t| t.parse().expect("LookAt number"))
        .collect();
    (cam, nums)
}

/// A 64×36 camera path over the generated island in DIR: `shotCam`, then its eye `dolly` of
/// the way toward its target ([`shot_cam_pose`]), written to DIR/dolly.json.
pub fn shot_cam_dolly_path(dir: &Path, dolly: f64) -> PathBuf {
    let file = serde_json::json!({
        "format": "motu-camera-path", "version": 1, "width": 64, "height": 36,
        "frames": [shot_cam_pose(dir, 0.0), shot_cam_pose(dir, dolly)],
    });
    let p = dir.join("dolly.json");
    std::fs::write(&p, serde_json::to_string_pretty(&file).expect("path JSON"))
        .expect("dolly.json");
    p
}

/// The default island's shotCam dolly ([`shot_cam_dolly_path`], 0.3 of the way) flown by
/// `motu bench --camera-path … --stream` as the viewer flies (one pass a frame, the coarse
/// fallback) at a quarter of its full build's peak, checked above the floor.
pub struct QuarterFlight {
    pub dir: tempfile::TempDir,
    pub pkg: PathBuf,
    pub path: PathBuf,
    pub budget: String,
}

impl QuarterFlight {
    /// `None` without a ray-tracing device (said loudly by [`gpu_available`]).
    pub fn new() -> Option<QuarterFlight> {
        let (dir, pkg) = gpu_island(None)?;
        let path = shot_cam_dolly_path(dir.path(), 0.3);
        let (peak, floor) = report_peak_and_floor(&pkg, "64", "36");
        assert!(
            peak / 4 > floor,
            "a quarter of {peak} is above the floor {floor}"
        );
        Some(QuarterFlight {
            dir,
            pkg,
            path,
            budget: (peak / 4).to_string(),
        })
    }

    /// The flight's `bench --json` report with `extra` flags (its build budget, frames, …),
    /// no warm-up renderer (on lavapipe each new trace pipeline is a fresh LLVM compile).
    pub fn bench(&self, extra: &[&str]) -> serde_json::Value {
        let mut args = vec![
            "bench",
            "--camera-path",
            s(&self.path),
            "--package",
            s(&self.pkg),
            "--stream",
            "--vram-budget",
            &self.budget,
            "--stream-fallback",
            "coarse",
            "--stream-passes",
            "1",
            "--warmup",
            "0",
            "--backend",
            "pipeline",
            "--json",
        ];
        args.extend(extra);
        motu_json(&args)
    }
}

/// `motu report --json` of `pkg` for a `width` × `height` image.
pub fn report_json(pkg: &Path, width: &str, height: &str) -> serde_json::Value {
    motu_json(&[
        "report",
        s(pkg),
        "--json",
        "--width",
        width,
        "--height",
        height,
    ])
}

/// A report's full-build peak and streaming floor (`variants[0].cost.peak_bytes`,
/// `streaming.min_resident_bytes`).
pub fn peak_and_floor(report: &serde_json::Value) -> (u64, u64) {
    (
        json_u64(&report["variants"][0]["cost"]["peak_bytes"]),
        json_u64(&report["streaming"]["min_resident_bytes"]),
    )
}

/// `motu report`'s full-build peak and streaming floor of `pkg` for a `width` × `height`
/// image ([`report_json`], [`peak_and_floor`]).
pub fn report_peak_and_floor(pkg: &Path, width: &str, height: &str) -> (u64, u64) {
    peak_and_floor(&report_json(pkg, width, height))
}

/// `v` as an unsigned integer; a panic naming what it was otherwise (stats and report JSON).
pub fn json_u64(v: &serde_json::Value) -> u64 {
    v.as_u64()
        .unwrap_or_else(|| panic!("expected an unsigned integer, got {v}"))
}

/// A scene from `shared/scenes` beside the checkout; `None` (with a loud line) if absent.
pub fn shared_scene(rel: &str) -> Option<PathBuf> {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/scenes")
        .join(rel);
    if p.exists() {
        Some(p)
    } else {
        eprintln!(
            "SKIPPED: {} not found (shared/scenes is not beside the checkout)",
            p.display()
        );
        None
    }
}

pub fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// Where tests leave files for people to look at (screenshots): `MOTU_TEST_ARTIFACTS`, else
/// `target/<profile>/test-artifacts`.
pub fn artifacts_dir() -> PathBuf {
    let dir = std::env::var_os("MOTU_TEST_ARTIFACTS")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            let exe = std::env::current_exe().expect("test executable path");
            exe.parent()
                .and_then(Path::parent)
                .expect("target/<profile>")
                .join("test-artifacts")
        });
    std::fs::create_dir_all(&dir).expect("artifacts dir");
    dir
}

/// Whether Debian's chromium is here; without it the test says so loudly, or fails when
/// `MOTU_REQUIRE_BROWSER=1` (CI).
pub fn chromium_available(test: &str) -> bool {
    let found = Command::new("chromium")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !found {
        assert!(
            std::env::var("MOTU_REQUIRE_BROWSER").map_or(true, |v| v.trim() != "1"),
            "MOTU_REQUIRE_BROWSER=1 but chromium is not installed (tools/setup.sh installs it)"
        );
        eprintln!("SKIPPED: chromium not installed: {test}");
    }
    found
}

/// Headless chromium on a local page with `mode` (`--dump-dom` or `--screenshot=FILE`);
/// returns (stdout, stderr). Flags keep it off the network.
pub fn chromium(page: &Path, mode: &str) -> (String, String) {
    let profile = tempfile_dir();
    let out = Command::new("timeout")
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
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg(mode)
        .arg(format!("file://{}", page.display()))
        .output()
        .expect("run chromium");
    let _ = std::fs::remove_dir_all(&profile);
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

fn tempfile_dir() -> PathBuf {
    use std::sync::atomic::{AtomicU32, Ordering};
    static N: AtomicU32 = AtomicU32::new(0);
    let dir = std::env::temp_dir().join(format!(
        "motu-chromium-{}-{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    ));
    std::fs::create_dir_all(&dir).expect("profile dir");
    dir
}

/// False (with a loud line) when no ray-tracing device exists and the run does not require one
/// (`MOTU_REQUIRE_GPU`, set by CI, turns that into a failure).
pub fn gpu_available() -> bool {
    let out = motu(&["devices", "--json"]);
    let ok = out.status.success()
        && String::from_utf8_lossy(&out.stdout).contains("\"ray_pipeline\": true");
    if !ok {
        assert!(
            std::env::var_os("MOTU_REQUIRE_GPU").is_none(),
            "MOTU_REQUIRE_GPU is set but no ray-tracing device was found"
        );
        eprintln!("SKIPPED: no Vulkan ray-tracing device");
    }
    ok
}

/// Whether some device has ray queries (the `query` backend).
pub fn has_ray_query() -> bool {
    String::from_utf8_lossy(&motu(&["devices", "--json"]).stdout).contains("\"ray_query\": true")
}

/// `motu import SCENE -o PKG EXTRA...`, asserting success.
pub fn import(scene: &Path, pkg: &Path, extra: &[&str]) {
    let mut args = vec!["import", s(scene), "-o", s(pkg)];
    args.extend(extra);
    motu_ok(&args);
}

/// `motu render` with `backend`, writing the AOV to `aov` (PNG and stats JSON beside it);
/// returns the stats. Pins `--bounces 0` unless `extra` names `--bounces`: the shaded view's
/// default diffuse bounce about doubles a shaded render's time on lavapipe, and these tests'
/// subjects are other things (streaming, hits, textures); tests of the default lighting use
/// [`render_default_lighting`].
pub fn render(pkg: &Path, backend: &str, aov: &Path, extra: &[&str]) -> serde_json::Value {
    render_env(pkg, backend, aov, extra, &[])
}

/// [`render`] with environment variables set (`--bounces 0` pinned the same way).
pub fn render_env(
    pkg: &Path,
    backend: &str,
    aov: &Path,
    extra: &[&str],
    env: &[(&str, &str)],
) -> serde_json::Value {
    let mut extra = extra.to_vec();
    if !extra.contains(&"--bounces") {
        extra.extend(["--bounces", "0"]);
    }
    render_unpinned(pkg, backend, aov, &extra, env)
}

/// [`render`] with `motu render`'s own lighting defaults (`--bounces` as the CLI sets it).
pub fn render_default_lighting(
    pkg: &Path,
    backend: &str,
    aov: &Path,
    extra: &[&str],
) -> serde_json::Value {
    render_unpinned(pkg, backend, aov, extra, &[])
}

fn render_unpinned(
    pkg: &Path,
    backend: &str,
    aov: &Path,
    extra: &[&str],
    env: &[(&str, &str)],
) -> serde_json::Value {
    let stats = aov.with_extension("json");
    let png = aov.with_extension("png");
    let mut args = vec![
        "render",
        s(pkg),
        "-o",
        s(&png),
        "--backend",
        backend,
        "--aov",
        s(aov),
        "--stats",
        s(&stats),
    ];
    args.extend(extra);
    motu_ok_env(&args, env);
    serde_json::from_str(&std::fs::read_to_string(&stats).expect("stats written"))
        .expect("stats JSON")
}

/// `--stream-rates` for tests that compare counts between runs or against recorded numbers:
/// the restore and store rules decide from these rates instead of this machine's measured
/// ones, which follow its load (lavapipe's restores cost about what its CPU builds do, so a
/// measured rule restores or builds by the noise: notes/rates52.md). Lavapipe-like, the
/// behaviour before the rules: restores (host or directory) far cheaper than builds, so every
/// cached BLAS is restored and every one built written; the same decisions on every run.
pub const PINNED_RATES: [&str; 2] = ["--stream-rates", "build=0.5,restore=4,disk_read=8,store=4"];

/// The per-frame counts of a streamed render (`--stats` JSON `st`): every integer and boolean
/// of each frame but its pass log (times are floats) and page faults, as `(frame, key,
/// value)`. With pinned rates ([`PINNED_RATES`]) two runs of one command give the same.
pub fn stream_frame_counts(st: &serde_json::Value) -> Vec<(usize, String, serde_json::Value)> {
    let mut out = Vec::new();
    for (i, f) in stream_frames(st).iter().enumerate() {
        let obj = f.as_object().expect("a frame object");
        // Page faults (`mesh_read_faults`, `mesh_copy_faults`) follow the OS's page cache,
        // not the streamer's decisions.
        for (k, v) in obj.iter().filter(|(k, _)| !k.ends_with("_faults")) {
            if v.is_u64() || v.is_boolean() {
                out.push((i, k.clone(), v.clone()));
            }
        }
    }
    out
}

/// The image size and frame count of a streamed camera path ([`streamed_path`]).
#[derive(Clone, Copy, Debug)]
pub struct PathShape {
    pub width: &'static str,
    pub height: &'static str,
    pub frames: &'static str,
}

/// The default camera's path in `shape` streamed under `budget` bytes on `backend`
/// (`--stream --stream-always`: the streamer itself, also at budgets that hold the whole
/// scene) with `extra` flags and `env`, its AOV written to `dir/name.aov`: the statistics and
/// the AOV's path. The stream tests' shot paths (`stream.rs`) and `stream_records.rs` run it.
/// Its rates are pinned ([`PINNED_RATES`]): these tests compare counts between runs and
/// against recorded numbers.
#[allow(clippy::too_many_arguments)]
pub fn streamed_path(
    pkg: &Path,
    dir: &Path,
    name: &str,
    budget: u64,
    backend: &str,
    shape: PathShape,
    extra: &[&str],
    env: &[(&str, &str)],
) -> (serde_json::Value, PathBuf) {
    let aov = dir.join(format!("{name}.aov"));
    let budget = budget.to_string();
    let mut args = vec![
        "--width",
        shape.width,
        "--height",
        shape.height,
        "--frames",
        shape.frames,
        "--stream",
        "--stream-always",
        "--vram-budget",
        &budget,
    ];
    args.extend(PINNED_RATES);
    args.extend(extra);
    (render_env(pkg, backend, &aov, &args, env), aov)
}

/// The TLAS piece tests' path shape (`stream_records.rs`, `stream_tlas_storage.rs`).
pub const PIECES_SHAPE: PathShape = PathShape {
    width: "48",
    height: "27",
    frames: "5",
};

/// The default camera's path in [`PIECES_SHAPE`] streamed on `pipeline` under `budget` bytes,
/// its root split into pieces of 3000 instances that are rebuilt (not updated), with `extra`
/// flags: the statistics and the AOV.
pub fn pieces_path(
    pkg: &Path,
    dir: &Path,
    name: &str,
    budget: u64,
    extra: &[&str],
) -> (serde_json::Value, PathBuf) {
    let mut args = vec![
        "--stream-split-instances",
        "3000",
        "--stream-tlas",
        "rebuild",
    ];
    args.extend(extra);
    streamed_path(pkg, dir, name, budget, "pipeline", PIECES_SHAPE, &args, &[])
}

/// The per-frame statistics of a streamed render (`--stats` JSON `st`).
pub fn stream_frames(st: &serde_json::Value) -> Vec<serde_json::Value> {
    st["stream"]["frames"].as_array().expect("frames").clone()
}

/// Key `k` summed over a streamed render's frames.
pub fn stream_total(st: &serde_json::Value, k: &str) -> u64 {
    stream_frames(st).iter().map(|f| json_u64(&f[k])).sum()
}

/// Checks a streamed camera path's probe rounds (`render --stream --stats` JSON `st`, at most
/// `max_rounds` a frame besides the verifying ones): every frame but the last probes its
/// successor's pixels once and then, in later rounds, only pixels left open (fewer than all
/// again each round), then in each verifying round (`probe_verify_rounds`, at most two) every
/// pixel again; the last frame has no successor and probes nothing. Returns how many frames ran
/// more than one round over open pixels.
pub fn check_probe_rounds(st: &serde_json::Value, max_rounds: u64) -> usize {
    // Names the key and the frame on failure (json_u64 alone would say only "got null").
    let field = |f: &serde_json::Value, k: &str| {
        f[k].as_u64()
            .unwrap_or_else(|| panic!("{k}: expected an unsigned integer in {f}"))
    };
    let pixels = field(st, "width") * field(st, "height");
    let frames = st["stream"]["frames"].as_array().expect("stream frames");
    let mut more = 0;
    for (i, f) in frames.iter().enumerate() {
        let (rounds, rays) = (field(f, "probe_rounds"), field(f, "probe_rays"));
        let verify = field(f, "probe_verify_rounds");
        if i + 1 == frames.len() {
            assert_eq!(
                (rounds, rays, verify),
                (0, 0, 0),
                "the last frame probes nothing: {f}"
            );
            continue;
        }
        assert!(verify <= 2 && verify < rounds, "verifying rounds: {f}");
        let (rounds, rays) = (rounds - verify, rays - verify * pixels);
        assert!((1..=max_rounds).contains(&rounds), "probe rounds: {f}");
        if rounds == 1 {
            assert_eq!(rays, pixels, "one round probes every pixel: {f}");
        } else {
            more += 1;
            assert!(
                rays > pixels && rays < rounds * pixels,
                "later rounds probe only the pixels left open: {f}"
            );
        }
    }
    more
}

/// A child process killed (and reaped) on drop: display servers outlive no test.
pub struct KillOnDrop(pub std::process::Child);

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Spawns the display server `cmd` (`name`, installed by the `package` that `tools/setup.sh`
/// installs) for window tests: `None` with a loud SKIPPED line when it cannot start, a failure
/// when `MOTU_REQUIRE_GPU` is set (CI).
pub fn spawn_display_server(
    mut cmd: Command,
    name: &str,
    package: &str,
    test: &str,
) -> Option<KillOnDrop> {
    match cmd.spawn() {
        Ok(c) => Some(KillOnDrop(c)),
        Err(e) => {
            assert!(
                std::env::var_os("MOTU_REQUIRE_GPU").is_none(),
                "MOTU_REQUIRE_GPU is set but {name} cannot start ({e}): tools/setup.sh installs {package}"
            );
            eprintln!("SKIPPED: {name} not available ({e}): {test}");
            None
        }
    }
}

/// A private X server for window tests (`motu view`): Xvfb on a display number it picks itself
/// (`-displayfd`), killed on drop.
pub struct Xvfb {
    _server: KillOnDrop,
    /// Xvfb's stdout, kept open: a closed pipe would kill it (SIGPIPE) if it wrote again.
    _stdout: std::io::BufReader<std::process::ChildStdout>,
    /// The `DISPLAY` value (`:N`).
    pub display: String,
}

/// Starts Xvfb; `None` (with a loud line) when it is not installed, a failure when
/// `MOTU_REQUIRE_GPU` is set (CI: `tools/setup.sh` installs `xvfb`).
pub fn xvfb(test: &str) -> Option<Xvfb> {
    use std::io::BufRead;
    let mut cmd = Command::new("Xvfb");
    cmd.args([
        "-displayfd",
        "1",
        "-screen",
        "0",
        "1024x768x24",
        "-nolisten",
        "tcp",
    ])
    .stdout(std::process::Stdio::piped())
    .stderr(std::process::Stdio::null());
    let mut server = spawn_display_server(cmd, "Xvfb", "xvfb", test)?;
    // Xvfb writes the display number once it accepts connections (a panic here drops, so
    // kills, the server).
    let mut line = String::new();
    let Some(mut stdout) = server.0.stdout.take().map(std::io::BufReader::new) else {
        panic!("Xvfb has no stdout pipe");
    };
    let read = stdout.read_line(&mut line);
    let n = line.trim().to_string();
    if read.is_err() || n.is_empty() {
        panic!("Xvfb started but reported no display number ({read:?})");
    }
    Some(Xvfb {
        display: format!(":{n}"),
        _server: server,
        _stdout: stdout,
    })
}

/// A private headless Wayland compositor for window tests (`motu view` on Wayland): weston's
/// headless backend on its own socket in its own runtime directory, killed on drop.
pub struct Weston {
    _server: KillOnDrop,
    runtime_dir: tempfile::TempDir,
    /// The `WAYLAND_DISPLAY` value (the socket's name in the runtime directory).
    pub socket: String,
}

/// Starts a headless weston; `None` (with a loud line) when it is not installed, a failure when
/// `MOTU_REQUIRE_GPU` is set (CI: `tools/setup.sh` installs `weston`).
pub fn weston(test: &str) -> Option<Weston> {
    use std::os::unix::fs::PermissionsExt;
    let runtime_dir = tempfile::tempdir().expect("runtime dir");
    // Wayland refuses runtime directories others can read.
    std::fs::set_permissions(runtime_dir.path(), std::fs::Permissions::from_mode(0o700))
        .expect("runtime dir mode");
    let socket = "motu-test".to_string();
    let mut cmd = Command::new("weston");
    cmd.args([
        "--backend=headless-backend.so",
        &format!("--socket={socket}"),
        "--width=1024",
        "--height=768",
        "--idle-time=0",
    ])
    .env("XDG_RUNTIME_DIR", runtime_dir.path())
    .env_remove("DISPLAY")
    .env_remove("WAYLAND_DISPLAY")
    .stdout(std::process::Stdio::null())
    .stderr(std::process::Stdio::null());
    let mut server = spawn_display_server(cmd, "weston", "weston", test)?;
    // The socket appears once weston accepts clients.
    let path = runtime_dir.path().join(&socket);
    let start = std::time::Instant::now();
    while !path.exists() {
        if let Ok(Some(status)) = server.0.try_wait() {
            panic!("weston exited before opening its socket: {status}");
        }
        if start.elapsed() > std::time::Duration::from_secs(30) {
            panic!("weston did not open {} within 30 s", path.display());
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    Some(Weston {
        _server: server,
        runtime_dir,
        socket,
    })
}

/// Runs `motu` on the Wayland compositor `w` (and no X display).
pub fn motu_on_wayland(w: &Weston, args: &[&str]) -> Output {
    Command::new(motu_bin())
        .args(args)
        .env("XDG_RUNTIME_DIR", w.runtime_dir.path())
        .env("WAYLAND_DISPLAY", &w.socket)
        .env_remove("DISPLAY")
        .output()
        .expect("spawning motu")
}

/// Runs `motu` with `DISPLAY` set to `display` (and no Wayland).
pub fn motu_on_display(display: &str, args: &[&str]) -> Output {
    Command::new(motu_bin())
        .args(args)
        .env("DISPLAY", display)
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .expect("spawning motu")
}

/// 128×128 RGB checker of 16×16-texel cells, two greys of moderate contrast (PFM: little
/// endian). Cells this large stay sharp at the mip level a 64×36 view picks.
fn write_checker_pfm(path: &Path) {
    const N: usize = 128;
    let mut bytes = format!("PF\n{N} {N}\n-1.0\n").into_bytes();
    for y in 0..N {
        for x in 0..N {
            let v = if (x / 16 + y / 16) % 2 == 0 {
                0.6f32
            } else {
                0.3
            };
            for _ in 0..3 {
                bytes.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    std::fs::write(path, bytes).unwrap();
}

/// A textured scene in `dir` (returns its `scene.pbrt`): a ground with a checker image texture
/// ([`write_checker_pfm`]; one mesh, one material, so its constant colour cannot tell the cells
/// apart) filling a 64×36 view of the scene's camera, [`CHECKER_CAMERA_POSE`], lit by a
/// distant light.
pub fn checker_scene(dir: &Path) -> PathBuf {
    write_checker_pfm(&dir.join("checker.pfm"));
    let scene = dir.join("scene.pbrt");
    // The ground fills the 64×36 view: 8 cells across, about 11 pixels each.
    std::fs::write(
        &scene,
        r#"LookAt 0 8 0  0 0 0  0 0 1
Camera "perspective" "float fov" [45]
WorldBegin
LightSource "distant" "point from" [0.3 10 0.2] "point to" [0 0 0] "rgb L" [2.5 2.5 2.5]
Texture "checks" "spectrum" "imagemap" "string filename" "checker.pfm"
AttributeBegin
  Material "matte" "texture Kd" "checks"
  Shape "trianglemesh" "point P" [-6 0 -6  6 0 -6  6 0 6  -6 0 6]
    "float uv" [0 0  1 0  1 1  0 1] "integer indices" [0 1 2  0 2 3]
AttributeEnd
"#,
    )
    .unwrap();
    scene
}

/// [`checker_scene`]'s camera as a camera-path pose (`motu render --camera-path`): the
/// importer's look-at frame of `LookAt 0 8 0  0 0 0  0 0 1` is exactly this (no rounding).
pub const CHECKER_CAMERA_POSE: &str =
    r#"{"eye": [0, 8, 0], "forward": [0, -1, 0], "up": [0, 0, 1], "fov_deg": 45}"#;
