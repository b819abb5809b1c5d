//! Issue 47: pictures a lighting artist recognises. `motu gen courtyard` is lit only by a sky
//! map (`infinite` with `mapname`) and a sun through a roof opening: the map is importance-
//! sampled as a light and shown where camera rays escape, `--exposure auto` picks the
//! exposure (`exposure_ev` in --stats), and the default `--bounces 1` adds diffuse light
//! bounced off what the sun and sky reach. The CPU oracle and both GPU backends agree
//! (docs/shading.md's tolerance), and streaming gives the full build's image, bounces
//! included.

use motu_tests::{
    gpu_available, has_ray_query, json_u64, motu_ok, render, render_default_lighting, s,
};
use std::collections::HashMap;
use std::path::Path;

fn read_png(path: &Path) -> Vec<[u8; 3]> {
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = dec.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgba);
    buf[..info.buffer_size()]
        .chunks_exact(4)
        .map(|p| [p[0], p[1], p[2]])
        .collect()
}

/// The share of the most common colour, and the standard deviation of luma (0–255).
fn colour_spread(px: &[[u8; 3]]) -> (f64, f64) {
    let mut counts: HashMap<[u8; 3], usize> = HashMap::new();
    for p in px {
        *counts.entry(*p).or_default() += 1;
    }
    let top = counts.values().copied().max().unwrap_or(0) as f64 / px.len() as f64;
    let luma: Vec<f64> = px
        .iter()
        .map(|p| 0.2126 * p[0] as f64 + 0.7152 * p[1] as f64 + 0.0722 * p[2] as f64)
        .collect();
    let mean = luma.iter().sum::<f64>() / luma.len() as f64;
    let var = luma.iter().map(|l| (l - mean) * (l - mean)).sum::<f64>() / luma.len() as f64;
    (top, var.sqrt())
}

/// docs/shading.md's tolerance for environment sampling and bounces between backends: the
/// same samples, so most pixels are equal; a direction whose trigonometry rounds differently
/// can change one ray's occlusion, so up to 2% of pixels may differ by more than two 8-bit
/// steps.
fn assert_within_tolerance(what: &str, a: &[[u8; 3]], b: &[[u8; 3]]) {
    assert_eq!(a.len(), b.len(), "{what}: sizes");
    let far = a
        .iter()
        .zip(b)
        .filter(|(p, q)| p.iter().zip(q.iter()).any(|(x, y)| x.abs_diff(*y) > 2))
        .count();
    assert!(
        far as f64 <= 0.02 * a.len() as f64,
        "{what}: {far} of {} pixels differ by more than 2 steps",
        a.len()
    );
}

fn courtyard(dir: &Path) -> std::path::PathBuf {
    motu_ok(&["gen", "courtyard", "-o", s(&dir.join("scene"))]);
    let pkg = dir.join("c.motu");
    motu_ok(&[
        "import",
        s(&dir.join("scene").join("scene.pbrt")),
        "-o",
        s(&pkg),
    ]);
    pkg
}

#[test]
fn courtyard_sky_map_sun_and_a_bounce() {
    let dir = tempfile::tempdir().unwrap();
    let pkg = courtyard(dir.path());
    let size = ["--width", "48", "--height", "48"];
    let at = |name: &str| dir.path().join(name);
    // Defaults: the sky map sampled, one diffuse bounce, auto exposure.
    let st1 = render_default_lighting(&pkg, "cpu", &at("b1.aov"), &size);
    let ev = st1["exposure_ev"].as_f64().expect("exposure_ev in --stats");
    assert!(
        ev.is_finite() && ev.abs() > 0.1,
        "auto exposure chose {ev} stops"
    );
    // Direct light only: the old look.
    let mut args = size.to_vec();
    args.extend(["--bounces", "0"]);
    render(&pkg, "cpu", &at("b0.aov"), &args);
    let b0 = read_png(&at("b0.png"));
    let b1 = read_png(&at("b1.png"));
    let (top0, _) = colour_spread(&b0);
    let (top1, sd1) = colour_spread(&b1);
    assert!(
        top1 < 0.30 && sd1 > 10.0,
        "with a bounce: {:.0}% of pixels share one colour, luma spread {sd1:.1}",
        top1 * 100.0
    );
    assert!(
        top0 > top1 + 0.03,
        "--bounces 0 shows the old look (more pixels without light): {:.1}% vs {:.1}%",
        top0 * 100.0,
        top1 * 100.0
    );
    // The bounce only adds light: at one exposure every pixel is at least as bright, and
    // many are brighter.
    let mut fixed = size.to_vec();
    fixed.extend(["--exposure", "0", "--bounces", "0"]);
    render(&pkg, "cpu", &at("f0.aov"), &fixed);
    fixed.truncate(fixed.len() - 2);
    fixed.extend(["--bounces", "1"]);
    render(&pkg, "cpu", &at("f1.aov"), &fixed);
    let (f0, f1) = (read_png(&at("f0.png")), read_png(&at("f1.png")));
    let brighter = f0
        .iter()
        .zip(&f1)
        .filter(|(a, b)| {
            assert!(a.iter().zip(b.iter()).all(|(x, y)| y >= x), "{a:?} → {b:?}");
            a != b
        })
        .count();
    assert!(
        brighter > f0.len() / 20,
        "only {brighter} pixels gained light"
    );

    if !gpu_available() {
        return;
    }
    let mut backends = vec!["pipeline"];
    if has_ray_query() {
        backends.push("query");
    }
    for b in backends {
        for (tag, extra) in [("d", &["--bounces", "0"][..]), ("b", &[][..])] {
            let mut args = size.to_vec();
            args.extend(extra);
            let aov = at(&format!("{b}_{tag}.aov"));
            render_default_lighting(&pkg, b, &aov, &args);
            let cpu = at(if tag == "d" { "b0.aov" } else { "b1.aov" });
            motu_ok(&["compare", s(&cpu), s(&aov), "--max-mismatch", "0"]);
            assert_within_tolerance(
                &format!("{b} {tag} vs cpu"),
                &read_png(&cpu.with_extension("png")),
                &read_png(&aov.with_extension("png")),
            );
        }
        // Streaming gives the full build's image with the default bounce (the sky map's
        // tables travel with each pass; each bounce ray waits, like a primary ray, for the
        // structures in front of its best hit).
        let mut args = size.to_vec();
        // Streamed although the budget holds the scene (else the full build renders it).
        args.extend(["--stream", "--stream-always"]);
        let aov = at(&format!("{b}_s.aov"));
        let st = render_default_lighting(&pkg, b, &aov, &args);
        let frame = &st["stream"]["frames"][0];
        assert!(
            frame["complete"] == true && json_u64(&frame["passes"]) >= 2,
            "{frame}"
        );
        let full = at(&format!("{b}_b.aov"));
        motu_ok(&["compare", s(&full), s(&aov), "--max-mismatch", "0"]);
        assert_within_tolerance(
            &format!("{b} streamed vs full, a bounce"),
            &read_png(&full.with_extension("png")),
            &read_png(&aov.with_extension("png")),
        );
    }
    // The samples are a fixed per-pixel sequence: a rerun is bit-identical.
    let mut args = size.to_vec();
    args.extend(["--bounces", "1"]);
    render(&pkg, "pipeline", &at("again.aov"), &args);
    assert_eq!(
        read_png(&at("again.png")),
        read_png(&at("pipeline_b.png")),
        "a rerun differs"
    );
}

#[test]
fn the_sky_maps_scale_is_honoured() {
    let dir = tempfile::tempdir().unwrap();
    motu_ok(&["gen", "courtyard", "-o", s(&dir.path().join("a"))]);
    let a = dir.path().join("a").join("scene.pbrt");
    let text = std::fs::read_to_string(&a).unwrap();
    // Sky only (no sun), then the same sky at a quarter through its `scale`.
    let sky_only: String = text
        .lines()
        .filter(|l| !l.contains("\"distant\""))
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(&a, &sky_only).unwrap();
    let b = dir.path().join("a").join("quarter.pbrt");
    let quarter = sky_only.replace(
        "\"rgb L\" [1 1 1]",
        "\"rgb L\" [1 1 1] \"rgb scale\" [0.25 0.25 0.25]",
    );
    assert_ne!(quarter, sky_only);
    std::fs::write(&b, quarter).unwrap();
    let mut sums = Vec::new();
    for (scene, name) in [(&a, "a"), (&b, "b")] {
        let pkg = dir.path().join(format!("{name}.motu"));
        motu_ok(&["import", s(scene), "-o", s(&pkg)]);
        let aov = dir.path().join(format!("{name}.aov"));
        render(
            &pkg,
            "cpu",
            &aov,
            &["--width", "32", "--height", "32", "--exposure", "0"],
        );
        let px = read_png(&aov.with_extension("png"));
        sums.push(px.iter().flatten().map(|&v| v as u64).sum::<u64>());
    }
    assert!(sums[0] > 0, "the sky lights the courtyard");
    assert!(
        (sums[1] as f64) < 0.75 * sums[0] as f64,
        "a quarter of the sky is darker: {sums:?}"
    );
}

/// `--ao-reach`: ambient-occlusion rays reach that fraction of the scene's diagonal. A reach
/// far below the default leaves less of the sky occluded (a brighter image at a fixed
/// exposure, never a darker pixel on average), and a value outside (0, 1000] is refused with
/// the range named.
#[test]
fn a_shorter_ao_reach_occludes_less_sky() {
    let dir = tempfile::tempdir().unwrap();
    let scene = motu_tests::gen_forest(dir.path(), &[]);
    let pkg = dir.path().join("f.motu");
    motu_ok(&["import", s(&scene), "-o", s(&pkg)]);
    let at = |name: &str| dir.path().join(name);
    let base = [
        "--width",
        "32",
        "--height",
        "24",
        "--exposure",
        "0",
        "--ao-samples",
        "4",
    ];
    render(&pkg, "cpu", &at("far.aov"), &base);
    let mut short = base.to_vec();
    short.extend(["--ao-reach", "0.0005"]);
    render(&pkg, "cpu", &at("near.aov"), &short);
    let luma = |px: &[[u8; 3]]| {
        px.iter()
            .map(|p| 0.2126 * p[0] as f64 + 0.7152 * p[1] as f64 + 0.0722 * p[2] as f64)
            .sum::<f64>()
            / px.len() as f64
    };
    let (far, near) = (read_png(&at("far.png")), read_png(&at("near.png")));
    assert_ne!(far, near, "--ao-reach 0.0005 changed no pixel");
    assert!(
        luma(&near) > luma(&far),
        "a shorter AO reach should occlude less sky: mean luma {:.2} against {:.2}",
        luma(&near),
        luma(&far)
    );
    let out = motu_tests::motu(&["render", s(&pkg), "-o", s(&at("x.png")), "--ao-reach", "0"]);
    assert!(!out.status.success(), "--ao-reach 0 was accepted");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("outside (0, 1000]"), "stderr: {err}");
    assert!(!at("x.png").exists(), "a refused render wrote its image");
}
