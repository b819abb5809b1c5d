//! A streamed render with the DEFAULT flags (no `--bounces`, exposure, spp, AO or backend
//! flags: the default bounce, auto exposure, the default backend) at a tight budget on a scene
//! written by others (bmw-m6, default import), 64×36: several passes, evicting, and still the
//! full build's image (AOV equal per pixel; colours within docs/shading.md's streamed
//! tolerance: one 8-bit step on at most 0.5% of the channels).

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
    if !gpu_available() {
        return;
    }
    let Some(scene) = motu_tests::shared_scene("bmw-m6/bmw-m6.pbrt") else {
        return;
    };
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
    let render = |tag: &str, extra: &[&str]| {
        let (png, aov, stats) = (
            d.join(format!("{tag}.png")),
            d.join(format!("{tag}.aov")),
            d.join(format!("{tag}.json")),
        );
        let mut args = vec!["render", s(&pkg), "-o", s(&png), "--aov", s(&aov)];
        args.extend(["--width", w, "--height", h, "--stats", s(&stats)]);
        args.extend_from_slice(extra);
        motu_ok(&args);
        let st: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&stats).unwrap()).unwrap();
        (png, aov, st)
    };
    let (fpng, faov, _) = render("full", &[]);
    let b = budget.to_string();
    let (spng, saov, st) = render("stream", &["--stream", "--vram-budget", &b]);
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
        "bmw_m6_streams_with_default_flags_as_the_full_build: {:.1} s (budget {budget} of peak {peak}, floor {floor}; {} passes, {} evicted)",
        t0.elapsed().as_secs_f64(),
        frame["passes"],
        frame["evicted"]
    );
}
