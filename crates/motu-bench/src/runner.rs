//! The runner: a scene's steps in child processes, turned into results and ratios.

use crate::plan::{ConfigSpec, SceneSpec, Settings, Source};
use crate::report::{ConfigResult, ImportMetrics, Ratios, RenderMetrics, SceneResult};
use crate::steps::{parse_json, run_step};
use motu_report::format_size;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

pub(crate) struct Runner {
    pub(crate) settings: Settings,
    pub(crate) work: PathBuf,
    pub(crate) logs: PathBuf,
    pub(crate) t0: Instant,
    pub(crate) progress: bool,
    pub(crate) deadline: Option<Duration>,
}

impl Runner {
    pub(crate) fn say(&self, msg: &str) {
        if self.progress {
            eprintln!("[{:7.1} s] {msg}", self.t0.elapsed().as_secs_f64());
        }
    }

    /// The step timeout, shortened to what is left before the deadline.
    fn timeout(&self) -> Duration {
        let step = Duration::from_secs(self.settings.step_timeout_s);
        match self.deadline {
            Some(d) => step
                .min(d.saturating_sub(self.t0.elapsed()))
                .max(Duration::from_secs(1)),
            None => step,
        }
    }

    fn past_deadline(&self) -> bool {
        self.deadline.is_some_and(|d| self.t0.elapsed() >= d)
    }

    /// Generates (or reuses) the scene; returns the entry file.
    fn scene(&self, spec: &SceneSpec, r: &mut SceneResult) -> Option<PathBuf> {
        let args = match &spec.source {
            Source::Shared { path } => {
                if path.exists() {
                    return Some(path.clone());
                }
                r.error = Some(format!("{} does not exist", path.display()));
                return None;
            }
            Source::Gen { args } => args,
        };
        let dir = self.work.join("scenes").join(spec.name);
        let stamp = dir.join("bench-gen.json");
        // Generated once: reuse a scene made with the same arguments by an earlier run.
        if let Ok(text) = std::fs::read_to_string(&stamp) {
            if let Ok(v) = serde_json::from_str::<Value>(&text) {
                if v["args"] == json!(args) && dir.join("scene.pbrt").exists() {
                    r.gen_cached = true;
                    r.gen = Some(v["gen"].clone());
                    r.gen_s = v["gen_s"].as_f64();
                    self.say(&format!("{}: reusing {}", spec.name, dir.display()));
                    return Some(dir.join("scene.pbrt"));
                }
            }
        }
        if dir.exists() {
            if let Err(e) = std::fs::remove_dir_all(&dir) {
                r.error = Some(format!("cannot clear {}: {e}", dir.display()));
                return None;
            }
        }
        // `motu gen` writes into an existing directory only (outputs are checked up front).
        if let Some(parent) = dir.parent() {
            if let Err(e) = std::fs::create_dir_all(parent) {
                r.error = Some(format!("cannot create {}: {e}", parent.display()));
                return None;
            }
        }
        self.say(&format!("{}: motu gen {}", spec.name, args.join(" ")));
        let mut full = vec!["gen".to_string()];
        full.extend(args.iter().cloned());
        full.extend([
            "-o".into(),
            dir.display().to_string(),
            "--width".into(),
            self.settings.width.to_string(),
            "--height".into(),
            self.settings.height.to_string(),
            "--json".into(),
        ]);
        let run = run_step(
            &full,
            &self.logs,
            &format!("{}-gen", spec.name),
            self.timeout(),
        );
        r.gen_s = Some(run.wall_s);
        if let Some(e) = run.error {
            r.error = Some(format!("gen: {e}"));
            return None;
        }
        let gen = match parse_json(&run.stdout) {
            Ok(v) => v,
            Err(e) => {
                r.error = Some(format!("gen: {e}"));
                return None;
            }
        };
        let stamp_body = json!({ "args": args, "gen": gen, "gen_s": run.wall_s });
        if let Err(e) = std::fs::write(&stamp, stamp_body.to_string()) {
            r.warnings
                .push(format!("cannot write {}: {e}", stamp.display()));
        }
        self.say(&format!(
            "{}: generated in {:.1} s ({}, {} flattened instances)",
            spec.name,
            run.wall_s,
            format_size(gen["bytes_written"].as_u64().unwrap_or(0)),
            gen["flattened_instances"].as_u64().unwrap_or(0)
        ));
        r.gen = Some(gen);
        Some(dir.join("scene.pbrt"))
    }

    fn import(
        &self,
        scene: &Path,
        pkg: &Path,
        tag: &str,
        extra: &[String],
    ) -> Result<ImportMetrics, String> {
        let mut args = vec![
            "import".to_string(),
            scene.display().to_string(),
            "-o".into(),
            pkg.display().to_string(),
        ];
        args.extend(extra.iter().cloned());
        args.push("--json".into());
        let run = run_step(&args, &self.logs, &format!("{tag}-import"), self.timeout());
        if let Some(e) = run.error {
            return Err(format!("import: {e}"));
        }
        let v = parse_json(&run.stdout).map_err(|e| format!("import: {e}"))?;
        let u = |k: &str| v[k].as_u64().unwrap_or(0);
        let f = |k: &str| v[k].as_f64().unwrap_or(0.0);
        Ok(ImportMetrics {
            wall_s: run.wall_s,
            parse_ms: f("parse_ms"),
            compile_ms: f("compile_ms"),
            pack_ms: f("pack_ms"),
            peak_rss_bytes: u("peak_rss_bytes"),
            file_bytes: u("file_bytes"),
            instances: u("instances"),
            flattened_instances: u("flattened_instances"),
            tlas_count: u("tlas_count"),
            blas_count: u("blas_count"),
        })
    }

    fn render(&self, pkg: &Path, tag: &str) -> Result<RenderMetrics, String> {
        let stats = self.logs.join(format!("{tag}-render.json"));
        let png = self.work.join("renders").join(format!("{tag}.png"));
        let s = &self.settings;
        let args: Vec<String> = vec![
            "bench".into(),
            "--child-render".into(),
            pkg.display().to_string(),
            "--child-stats".into(),
            stats.display().to_string(),
            "--child-png".into(),
            png.display().to_string(),
            "--backend".into(),
            s.backend.into(),
            "--width".into(),
            s.width.to_string(),
            "--height".into(),
            s.height.to_string(),
            "--frames".into(),
            s.frames.to_string(),
            "--warmup".into(),
            s.warmup_frames.to_string(),
        ];
        let run = run_step(&args, &self.logs, &format!("{tag}-render"), self.timeout());
        if let Some(e) = run.error {
            return Err(format!("render: {e}"));
        }
        let text = std::fs::read_to_string(&stats)
            .map_err(|e| format!("render: reading {}: {e}", stats.display()))?;
        serde_json::from_str(&text)
            .map_err(|e| format!("render: bad stats {}: {e}", stats.display()))
    }

    pub(crate) fn run_scene(&self, spec: &SceneSpec) -> SceneResult {
        let mut r = SceneResult {
            name: spec.name,
            source: spec.source.clone(),
            note: spec.note.clone(),
            scene_path: None,
            gen_s: None,
            gen_cached: false,
            gen: None,
            error: None,
            warnings: Vec::new(),
            configs: Vec::new(),
        };
        if self.past_deadline() {
            r.configs = spec
                .configs
                .iter()
                .map(|c| skipped(c, "not run: --deadline-s reached"))
                .collect();
            return r;
        }
        let Some(scene) = self.scene(spec, &mut r) else {
            self.say(&format!(
                "{}: FAILED {}",
                spec.name,
                r.error.as_deref().unwrap_or("")
            ));
            r.configs = spec
                .configs
                .iter()
                .map(|c| failed(c, r.error.clone().unwrap_or_default(), None))
                .collect();
            return r;
        };
        r.scene_path = Some(scene.clone());
        if let (Some(limit), Some(n)) = (
            spec.must_exceed_instances,
            r.gen
                .as_ref()
                .and_then(|g| g["flattened_instances"].as_u64()),
        ) {
            if n <= limit {
                r.warnings.push(format!(
                    "{n} flattened instances do not exceed {limit}: raise --island-scale so that `sl` needs TLAS splits"
                ));
            }
        }
        let pkg_dir = self.work.join("packages");
        for c in &spec.configs {
            if self.past_deadline() {
                r.configs.push(skipped(c, "not run: --deadline-s reached"));
                continue;
            }
            let tag = format!("{}-{}", spec.name, c.label.replace('+', "-"));
            let pkg = pkg_dir.join(format!("{tag}.motu"));
            self.say(&format!("{tag}: import {}", c.import_args.join(" ")));
            let import = match self.import(&scene, &pkg, &tag, &c.import_args) {
                Ok(m) => m,
                Err(e) => {
                    self.say(&format!("{tag}: FAILED {e}"));
                    let _ = std::fs::remove_file(&pkg);
                    r.configs.push(failed(c, e, None));
                    continue;
                }
            };
            self.say(&format!(
                "{tag}: imported in {:.1} s (peak RSS {}, {}, {} TLAS / {} BLAS); render {}×{} {} ({}+{} frames)",
                import.wall_s,
                format_size(import.peak_rss_bytes),
                format_size(import.file_bytes),
                import.tlas_count,
                import.blas_count,
                self.settings.width,
                self.settings.height,
                self.settings.backend,
                self.settings.warmup_frames,
                self.settings.frames,
            ));
            let render = self.render(&pkg, &tag);
            if !self.settings.keep_packages {
                // Packages of the big scenes are tens of GB: keep only one at a time.
                let _ = std::fs::remove_file(&pkg);
            }
            match render {
                Ok(m) => {
                    self.say(&format!(
                        "{tag}: {:.2} ms/frame, {:.1} Mrays/s, AS {} (build {:.0} ms), child {:.1} s",
                        m.ms_per_frame,
                        m.rays_per_second / 1e6,
                        format_size(m.as_bytes),
                        m.as_build_ms,
                        m.wall_s
                    ));
                    r.configs.push(ConfigResult {
                        label: c.label.clone(),
                        import_args: c.import_args.clone(),
                        status: "ok",
                        error: None,
                        import: Some(import),
                        render: Some(m),
                        ratios: Ratios::default(),
                    });
                }
                Err(e) => {
                    self.say(&format!("{tag}: FAILED {e}"));
                    r.configs.push(failed(c, e, Some(import)));
                }
            }
        }
        fill_ratios(&mut r.configs);
        r
    }
}

fn skipped(c: &ConfigSpec, why: &str) -> ConfigResult {
    ConfigResult {
        status: "skipped",
        ..failed(c, why.to_string(), None)
    }
}

fn failed(c: &ConfigSpec, error: String, import: Option<ImportMetrics>) -> ConfigResult {
    ConfigResult {
        label: c.label.clone(),
        import_args: c.import_args.clone(),
        status: "failed",
        error: Some(error),
        import,
        render: None,
        ratios: Ratios::default(),
    }
}

/// Ratios against the scene's `sl` configuration (absent when either side is missing or 0).
pub(crate) fn fill_ratios(configs: &mut [ConfigResult]) {
    let Some(base) = configs.iter().find(|c| c.label == "sl").cloned() else {
        return;
    };
    let ratio = |num: Option<f64>, den: Option<f64>| match (num, den) {
        (Some(n), Some(d)) if n > 0.0 && d > 0.0 => Some(n / d),
        _ => None,
    };
    let rays = |c: &ConfigResult| c.render.as_ref().map(|m| m.rays_per_second);
    let as_bytes = |c: &ConfigResult| c.render.as_ref().map(|m| m.as_bytes as f64);
    let rss = |c: &ConfigResult| c.import.as_ref().map(|m| m.peak_rss_bytes as f64);
    for c in configs.iter_mut() {
        c.ratios = Ratios {
            rays_per_second_vs_sl: ratio(rays(c), rays(&base)),
            as_bytes_sl_over_this: ratio(as_bytes(&base), as_bytes(c)),
            import_peak_rss_vs_sl: ratio(rss(c), rss(&base)),
        };
    }
}
