//! Issue 45.6 (calls53): where a streamed pass's proxy work goes. The counting mode
//! (`MOTU_PROXY_TESTS=count`, a specialisation constant of the streamed shaders) splits each
//! pass's proxy intersection-shader calls, reports, member tests and rays by ray kind (camera,
//! guard, shadow, AO, bounce) and outcome (open, closed, miss): `pass_log`'s `proxy_calls_*`.
//! The pipeline's open bound (`shaders/pipeline/open_bound.glsl`) may only take member tests
//! from rays that met an open structure: the same rays, the same calls, the same images.

use motu_tests::{
    gpu_island, json_u64 as u, render_env, report_peak_and_floor, s, shot_cam_dolly_path,
    stream_frames,
};

const KINDS: [&str; 5] = ["camera", "guard", "shadow", "ao", "bounce"];
const OUTCOMES: [&str; 3] = ["open", "closed", "miss"];

/// Every pass of every frame.
fn passes(st: &serde_json::Value) -> Vec<serde_json::Value> {
    stream_frames(st)
        .iter()
        .flat_map(|f| f["pass_log"].as_array().expect("pass_log").clone())
        .collect()
}

/// Pass `p`'s counter `field` of `kind` rays ending `outcome`.
fn work(p: &serde_json::Value, kind: &str, outcome: &str, field: &str) -> u64 {
    u(&p[format!("proxy_calls_{kind}")][outcome][field])
}

/// `field` summed over the kinds and outcomes `pick` keeps, over every pass.
fn total(st: &serde_json::Value, field: &str, pick: impl Fn(&str, &str) -> bool) -> u64 {
    let mut n = 0;
    for p in passes(st) {
        for k in KINDS {
            for o in OUTCOMES {
                if pick(k, o) {
                    n += work(&p, k, o, field);
                }
            }
        }
    }
    n
}

/// Per pass: the counts the bound leaves as they are, and every kind's rays and calls.
fn fixed_counts(st: &serde_json::Value) -> Vec<Vec<u64>> {
    let keys = [
        "traced",
        "open_pixels",
        "open_closest",
        "secondary_rays",
        "tlas_walks",
        "mark_walks",
        "needed",
        "blas_built",
        "evicted",
    ];
    passes(st)
        .iter()
        .map(|p| {
            let mut v: Vec<u64> = keys.iter().map(|k| u(&p[*k])).collect();
            for k in KINDS {
                for o in OUTCOMES {
                    v.extend([work(p, k, o, "rays"), work(p, k, o, "calls")]);
                }
            }
            v
        })
        .collect()
}

#[test]
fn counted_proxy_calls_split_by_ray_kind_and_the_open_bound_cuts_only_open_rays_members() {
    let Some((dir, pkg)) = gpu_island(None) else {
        return;
    };
    let d = dir.path();
    let path = shot_cam_dolly_path(d, 0.3);
    let (peak, floor) = report_peak_and_floor(&pkg, "64", "36");
    assert!(peak / 4 > floor, "a quarter of {peak} is above {floor}");
    let budget = (peak / 4).to_string();
    // The viewer's refining frames (8 MiB of building a frame leaves pixels open), with a
    // bounce so every ray kind is traced.
    let args = [
        "--camera-path",
        s(&path),
        "--frames",
        "6",
        "--stream",
        "--stream-always",
        "--vram-budget",
        &budget,
        "--stream-build-budget",
        "8MiB",
        "--stream-fallback",
        "coarse",
        "--no-as-cache",
        "--host-cache",
        "0",
        "--bounces",
        "1",
    ];
    let run = |name: &str, env: &[(&str, &str)]| {
        let aov = d.join(format!("{name}.aov"));
        (render_env(&pkg, "pipeline", &aov, &args, env), aov)
    };
    let (plain, plain_aov) = run("plain", &[]);
    let (off, off_aov) = run("unbounded", &[("MOTU_PROXY_TESTS", "count,unbounded")]);
    let (on, on_aov) = run("bounded", &[("MOTU_PROXY_TESTS", "count")]);

    // Off by default: nothing counted.
    assert_eq!(
        total(&plain, "rays", |_, _| true),
        0,
        "no counts without the mode"
    );

    for st in [&off, &on] {
        for p in passes(st) {
            // Every secondary ray (shadow, AO, bounce) is counted once, under its kind.
            let secondary: u64 = ["shadow", "ao", "bounce"]
                .iter()
                .flat_map(|k| OUTCOMES.map(|o| work(&p, k, o, "rays")))
                .sum();
            assert_eq!(secondary, u(&p["secondary_rays"]), "{p}");
            let primary: u64 = ["camera", "guard"]
                .iter()
                .flat_map(|k| OUTCOMES.map(|o| work(&p, k, o, "rays")))
                .sum();
            assert!(primary <= u(&p["traced"]), "{p}");
            for k in KINDS {
                for o in OUTCOMES {
                    assert!(work(&p, k, o, "reports") <= work(&p, k, o, "calls"), "{p}");
                }
            }
        }
        // Every kind was traced, and most calls report nothing (the quantised members reject).
        for k in ["camera", "shadow", "ao", "bounce"] {
            assert!(total(st, "rays", |kk, _| kk == k) > 0, "{k} rays counted");
        }
        let (calls, reports) = (
            total(st, "calls", |_, _| true),
            total(st, "reports", |_, _| true),
        );
        eprintln!("calls {calls}, reports {reports}");
        assert!(calls > 10 * reports, "calls {calls}, reports {reports}");
    }

    // The bound: the same rays, calls, walks, requests and builds; the same AOV and colour,
    // counted or not.
    assert_eq!(
        fixed_counts(&on),
        fixed_counts(&off),
        "only member tests change"
    );
    for ext in ["aov", "png"] {
        let a = std::fs::read(off_aov.with_extension(ext)).expect("unbounded output");
        let b = std::fs::read(on_aov.with_extension(ext)).expect("bounded output");
        let c = std::fs::read(plain_aov.with_extension(ext)).expect("plain output");
        assert!(a == b && b == c, "the {ext} is byte-equal");
    }
    // Rays that met no open structure keep every member test (their bound never fell; guard
    // rays left out: their mark walks skip BLASes other rays marked first, a race).
    let missed =
        |st: &serde_json::Value| total(st, "member_tests", |k, o| o == "miss" && k != "guard");
    assert_eq!(
        missed(&on),
        missed(&off),
        "a ray that met no open structure tests the same"
    );
    // Open camera rays lose the members of boxes behind their nearest open entry.
    let open_camera =
        |st: &serde_json::Value| total(st, "member_tests", |k, o| o == "open" && k == "camera");
    let (o_off, o_on) = (open_camera(&off), open_camera(&on));
    eprintln!("open camera rays' member tests {o_off} -> {o_on}");
    assert!(o_off > 0, "open camera rays counted");
    assert!(o_on * 100 <= o_off * 85, "{o_off} -> {o_on}: at most 85%");
}
