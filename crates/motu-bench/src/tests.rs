use super::*;
use crate::child::median;
use crate::runner::fill_ratios;
use crate::steps::run_step;

fn result(label: &str, rays_per_second: f64, as_bytes: u64, rss: u64) -> ConfigResult {
    ConfigResult {
        label: label.into(),
        import_args: Vec::new(),
        status: "ok",
        error: None,
        import: Some(ImportMetrics {
            peak_rss_bytes: rss,
            ..Default::default()
        }),
        render: Some(RenderMetrics {
            rays_per_second,
            as_bytes,
            ..Default::default()
        }),
        ratios: Ratios::default(),
    }
}

#[test]
fn ratios_are_against_the_sl_configuration_of_the_same_run() {
    let mut c = vec![
        result("ml", 60.0, 10, 100),
        result("sl", 100.0, 400, 200),
        result("levels2", 0.0, 0, 0),
    ];
    fill_ratios(&mut c);
    assert_eq!(c[0].ratios.rays_per_second_vs_sl, Some(0.6));
    assert_eq!(c[0].ratios.as_bytes_sl_over_this, Some(40.0));
    assert_eq!(c[0].ratios.import_peak_rss_vs_sl, Some(0.5));
    assert_eq!(c[1].ratios.rays_per_second_vs_sl, Some(1.0));
    // Zero (e.g. a failed render) gives no ratio rather than infinity.
    assert_eq!(c[2].ratios.rays_per_second_vs_sl, None);
    assert_eq!(c[2].ratios.as_bytes_sl_over_this, None);
}

#[test]
fn no_sl_means_no_ratios() {
    let mut c = vec![result("ml", 60.0, 10, 1)];
    fill_ratios(&mut c);
    assert!(c[0].ratios.rays_per_second_vs_sl.is_none());
}

#[test]
fn median_is_the_middle_of_sorted_times() {
    assert_eq!(median(&mut [5.0, 1.0, 3.0]), 3.0);
    assert_eq!(median(&mut []), 0.0);
}

#[test]
fn a_failing_child_is_recorded_not_raised() {
    let dir = tempdir();
    // `motu-cli`'s test binary is not motu: any arguments make it fail, which is the point.
    let run = run_step(
        &["--definitely-not-a-flag".into()],
        &dir,
        "t",
        Duration::from_secs(60),
    );
    assert!(run.error.is_some(), "{run:?}");
    assert!(dir.join("t.err").exists());
    std::fs::remove_dir_all(&dir).ok();
}

/// The suite's configurations, pinned: labels and `motu import` arguments per scene.
#[test]
fn plans_keep_their_configurations() {
    let configs = |quick: bool| -> Vec<String> {
        let a = SuiteOptions {
            suite: "cpu".into(),
            quick,
            scenes: Some(PathBuf::from("/nonexistent/shared/scenes")),
            ..Default::default()
        };
        let s = plan::settings(&a).unwrap();
        plan::plan(&s, &a)
            .unwrap()
            .iter()
            .flat_map(|sc| {
                sc.configs
                    .iter()
                    .map(|c| format!("{} {}: {}", sc.name, c.label, c.import_args.join(" ")))
            })
            .collect()
    };
    let std = |scene: &str| {
        [
            format!("{scene} sl: --levels sl"),
            format!("{scene} ml: --levels ml"),
            format!("{scene} levels2: --levels 2"),
            format!("{scene} auto: --levels auto"),
        ]
    };
    let mut want: Vec<String> = std("forest")
        .into_iter()
        .chain(std("sphereflake"))
        .collect();
    want.extend(
        [
            "lod-grid sl: --levels sl",
            "lod-grid ml: --levels ml",
            "lod-grid sl+lod: --levels sl --lod 4",
            "lod-grid ml+lod: --levels ml --lod 4",
            "buddha-fractal sl: --levels sl",
            "buddha-fractal ml: --levels ml",
        ]
        .map(String::from),
    );
    let mut full = want.clone();
    full.extend(["island sl: --levels sl", "island ml: --levels ml"].map(String::from));
    assert_eq!(configs(false), full);
    want.extend(
        [
            "island sl: --levels sl --max-instances 1500",
            "island ml: --levels ml --max-instances 1500",
        ]
        .map(String::from),
    );
    assert_eq!(configs(true), want);
}

fn tempdir() -> PathBuf {
    let d = std::env::temp_dir().join(format!("motu-bench-test-{}", std::process::id()));
    std::fs::create_dir_all(&d).ok();
    d
}
