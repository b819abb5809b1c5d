//! Issue 47 item 7, end to end: a click on the viewer's egui panel changes what the next frame
//! renders. A scripted run cannot click a real window, so `motu view --panel-click
//! FRAME:LABEL` feeds egui synthetic pointer events (hover, press, release) at the widget
//! the panel laid out with that label, inside the real view loop (Xvfb, lavapipe, the
//! swapchain): the panel's own input path, its `Controls`, the source's element rebuild and the
//! frame read back from the swapchain.

use motu_tests::{gen_island, gpu_available, motu, motu_json, motu_ok, motu_on_display, s, xvfb};
use std::path::Path;

fn decode_png(p: &Path) -> Vec<u8> {
    let dec = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(p).expect("png"),
    ));
    let mut r = dec.read_info().expect("png header");
    let mut buf = vec![0; r.output_buffer_size().expect("png size")];
    let info = r.next_frame(&mut buf).expect("png frame");
    buf.truncate(info.buffer_size());
    buf
}

/// Unticking an element's checkbox in the panel takes it out of the next frame: the AOV and
/// image after the click equal `motu render --subset` of the other elements, and differ from
/// the same run without the click.
#[test]
fn a_panel_click_on_an_element_changes_the_next_frame() {
    if !gpu_available() {
        return;
    }
    let Some(x) = xvfb("a_panel_click_on_an_element_changes_the_next_frame") else {
        return;
    };
    let t0 = std::time::Instant::now();
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pkg = gen_island(d, None);
    let info = motu_json(&["info", s(&pkg), "--elements", "--json"]);
    let names: Vec<String> = info["elements"]
        .as_array()
        .expect("elements")
        .iter()
        .map(|e| e["name"].as_str().unwrap().to_string())
        .collect();
    let clicked = "isBeach";
    assert!(names.iter().any(|n| n == clicked), "{names:?}");
    // The panel needs room for its element list; the ids view keeps the frames cheap.
    let size = ["--width", "200", "--height", "440"];
    let view = |tag: &str, click: Option<&str>| {
        let (png, aov) = (d.join(format!("{tag}.png")), d.join(format!("{tag}.aov")));
        let mut args = vec!["view", s(&pkg)];
        args.extend(size);
        args.extend([
            "--backend",
            "pipeline",
            "--view",
            "ids",
            "--frames",
            "6",
            "--overlay",
            "--screenshot",
            s(&png),
            "--aov",
            s(&aov),
        ]);
        let arg;
        if let Some(c) = click {
            arg = format!("2:{c}");
            args.extend(["--panel-click", &arg]);
        }
        let out = motu_on_display(&x.display, &args);
        let err = String::from_utf8_lossy(&out.stderr).into_owned();
        assert!(out.status.success(), "motu {}:\n{err}", args.join(" "));
        (png, aov)
    };
    // Clicked at frame 2 (egui sizes its window in frame 0 and lays it out in 1; hover 2, press
    // 3, release 4): frame 5, the last, renders without it.
    let (cpng, caov) = view("clicked", Some(clicked));
    let (upng, uaov) = view("unclicked", None);
    let rest: Vec<&str> = names
        .iter()
        .map(String::as_str)
        .filter(|n| *n != clicked)
        .collect();
    let rest = rest.join(",");
    let (rpng, raov) = (d.join("render.png"), d.join("render.aov"));
    let mut args = vec!["render", s(&pkg), "-o", s(&rpng), "--aov", s(&raov)];
    args.extend(size);
    args.extend(["--backend", "pipeline", "--view", "ids", "--subset", &rest]);
    motu_ok(&args);
    let out = motu_ok(&["compare", s(&caov), s(&raov), "--max-mismatch", "0"]);
    assert!(
        out.contains("(0 of "),
        "clicked view vs render --subset: {out}"
    );
    assert!(
        decode_png(&cpng) == decode_png(&rpng),
        "the clicked frame's swapchain image differs from motu render --subset's PNG"
    );
    // Without the click the element is there: the click made the difference.
    let diff = motu(&["compare", s(&uaov), s(&raov), "--max-mismatch", "0"]);
    assert!(
        !diff.status.success(),
        "the unclicked run should still show {clicked}"
    );
    assert!(decode_png(&upng) != decode_png(&cpng));
    // A label the panel does not show fails the run, naming it.
    let out = motu_on_display(
        &x.display,
        &[
            "view",
            s(&pkg),
            "--width",
            "64",
            "--height",
            "36",
            "--view",
            "ids",
            "--frames",
            "5",
            "--overlay",
            "--panel-click",
            "2:noSuchElement",
        ],
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "an unplayable click must fail");
    assert!(err.contains("noSuchElement"), "{err}");
    eprintln!(
        "a_panel_click_on_an_element_changes_the_next_frame: {:.1} s",
        t0.elapsed().as_secs_f64()
    );
}
