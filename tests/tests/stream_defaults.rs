//! A streamed render with the DEFAULT flags (no `--bounces`, exposure, spp, AO or backend
//! flags: the default bounce, auto exposure, the default backend) at a tight budget on a scene
//! written by others (bmw-m6, default import), 64×36: several passes, evicting, and still the
//! full build's image (AOV equal per pixel; colours within docs/shading.md's streamed
//! tolerance: one 8-bit step on at most 0.5% of the channels); and the same with a shorter
//! `--ao-reach`, against the full build with that reach.

use motu_tests::{gpu_available, json_u64 as u, motu_ok, peak_and_floor, report_json, s};
use std::path::Path;

fn read_png(path: &Path) -> Vec<u8> {
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut r = dec.read_info().unwrap();
    let mut buf = vec![0u8; r.output_buffer_size().unwrap()];
    let info = r.next_frame(&mut buf).unwrap();
    buf.truncate(info.buffer_size());
    buf
}

#[test]
fn bmw_m6_streams_with_default_flags_as_the_full_build() {
    streams_as_the_full_build("bmw_m6_streams_with_default_flags_as_the_full_build", &[]);
}

/// `--ao-reach` (issue 45's lever for the streamed working set) changes the image, so a
/// streamed render with it must equal the full build with the same reach, and differ from the
/// default reach's (the flag took effect).
#[test]
fn a_shorter_ao_reach_streams_as_the_full_build_with_the_same_reach() {
    let Some(shorter) = streams_as_the_full_build(
        "a_shorter_ao_reach_streams_as_the_full_build_with_the_same_reach",
        &["--ao-reach", "0.03"],
    ) else {
        return;
    };
    let Some(default) = streams_as_the_full_build("(default reach)", &[]) else {
        return;
    };
    let changed = shorter.iter().zip(&default).filter(|(a, b)| a != b).count();
    assert!(
        changed > 0,
        "--ao-reach 0.03 changed no channel of the full build's image"
    );
}

/// Renders bmw-m6 (64×36) by the full build and streamed at a tight budget, both with `extra`;
/// asserts the streamed frame several passes and evicting, its AOV equal per pixel and its
/// colours within the streamed tolerance; returns the full build's pixels (None: no GPU or
/// no shared scenes).
fn streams_as_the_full_build(test: &str, extra: &[&str]) -> Option<Vec<u8>> {
    if !gpu_available() {
        return None;
    }
    let scene = motu_tests::shared_scene("bmw-m6/bmw-m6.pbrt")?;
    let t0 = std::time::Instant::now();
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pkg = d.join("bmw.motu");
    motu_ok(&["import", s(&scene), "-o", s(&pkg)]);
    let (w, h) = ("64", "36");
    let (peak, floor) = peak_and_floor(&report_json(&pkg, w, h));
    // Tight: an eighth of the way from the floor to the full build's peak.
    let budget = floor + (peak.saturating_sub(floor)) / 8;
    assert!(budget < peak / 2, "floor {floor}, peak {peak}: not tight");
    let render = |tag: &str, more: &[&str]| {
        let (png, aov, stats) = (
            d.join(format!("{tag}.png")),
            d.join(format!("{tag}.aov")),
            d.join(format!("{tag}.json")),
        );
        let mut args = vec!["render", s(&pkg), "-o", s(&png), "--aov", s(&aov)];
        args.extend(["--width", w, "--height", h, "--stats", s(&stats)]);
        args.extend_from_slice(extra);
        args.extend_from_slice(more);
        motu_ok(&args);
        let st: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&stats).unwrap()).unwrap();
        (png, aov, st)
    };
    let (fpng, faov, _) = render("full", &[]);
    let b = budget.to_string();
    // Fixed rates: the frame's evictions return (restored or built) as on every machine.
    let (spng, saov, st) = render(
        "stream",
        &[
            "--stream",
            "--vram-budget",
            &b,
            motu_tests::PINNED_RATES[0],
            motu_tests::PINNED_RATES[1],
        ],
    );
    let frame = &st["stream"]["frames"][0];
    assert_eq!(frame["complete"], true, "{frame}");
    assert!(u(&frame["passes"]) >= 3, "several passes: {frame}");
    assert!(u(&frame["evicted"]) > 0, "evicting: {frame}");
    assert!(u(&st["vram_peak_bytes"]) <= budget, "{st}");
    let out = motu_ok(&["compare", s(&faov), s(&saov), "--max-mismatch", "0"]);
    assert!(out.contains("(0 of "), "{out}");
    let (full, streamed) = (read_png(&fpng), read_png(&spng));
    assert_eq!(full.len(), streamed.len());
    let mut one_step = 0usize;
    for (a, b) in full.iter().zip(&streamed) {
        let diff = a.abs_diff(*b);
        assert!(diff <= 1, "a channel differs by {diff} 8-bit steps");
        one_step += usize::from(diff == 1);
    }
    assert!(
        one_step * 200 <= full.len(),
        "{one_step} of {} channels differ by one step (at most 0.5%)",
        full.len()
    );
    eprintln!(
        "{test}: {:.1} s (budget {budget} of peak {peak}, floor {floor}; {} passes, {} evicted)",
        t0.elapsed().as_secs_f64(),
        frame["passes"],
        frame["evicted"]
    );
    Some(full)
}
