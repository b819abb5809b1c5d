use super::*;
use crate::SourceStats;
use egui::epaint::{ClippedShape, Shape};
use motu_gpu::View;

fn info() -> PanelInfo {
    PanelInfo {
        width: 64,
        height: 36,
        backend: "pipeline",
        frame_ms: 12.5,
        gpu_ms: 3.25,
        rays_per_second: 2e6,
        traces_per_ray: 1.0,
        exposure_ev: -1.5,
        stats: SourceStats {
            vram_used_bytes: 1 << 20,
            vram_budget_bytes: 2 << 20,
            resident_structures: 3,
            total_structures: 7,
            passes: 4,
            streaming: Some((5, 2)),
            incomplete_pixels: 0,
            tlas_pieces_stale: 0,
            lod_mode: "instance",
            stream_fit: None,
        },
        samples: 16,
        denoised: false,
    }
}

/// Every text egui laid out, with its screen rectangle.
fn texts(shapes: &[ClippedShape]) -> Vec<(String, egui::Rect)> {
    fn walk(s: &Shape, out: &mut Vec<(String, egui::Rect)>) {
        match s {
            Shape::Text(t) => out.push((
                t.galley.text().to_string(),
                t.galley.rect.translate(t.pos.to_vec2()),
            )),
            Shape::Vec(v) => v.iter().for_each(|s| walk(s, out)),
            _ => {}
        }
    }
    let mut out = Vec::new();
    shapes.iter().for_each(|c| walk(&c.shape, &mut out));
    out
}

fn input(events: Vec<egui::Event>) -> egui::RawInput {
    egui::RawInput {
        screen_rect: Some(egui::Rect::from_min_size(
            egui::Pos2::ZERO,
            egui::vec2(800.0, 900.0),
        )),
        events,
        ..Default::default()
    }
}

fn frame(
    ctx: &egui::Context,
    ctl: &mut Controls,
    history: &History,
    events: Vec<egui::Event>,
) -> egui::FullOutput {
    ctx.run(input(events), |ctx| build(ctx, &info(), history, ctl))
}

fn click(at: egui::Pos2, pressed: bool) -> egui::Event {
    egui::Event::PointerButton {
        pos: at,
        button: egui::PointerButton::Primary,
        pressed,
        modifiers: egui::Modifiers::NONE,
    }
}

/// Clicks the widget whose text is `label` (laid out in `shapes`).
fn click_text(ctx: &egui::Context, ctl: &mut Controls, shapes: &[ClippedShape], label: &str) {
    let at = texts(shapes)
        .into_iter()
        .find(|(t, _)| t == label)
        .unwrap_or_else(|| panic!("no {label:?} in the panel"))
        .1
        .center();
    let h = History::default();
    frame(ctx, ctl, &h, vec![egui::Event::PointerMoved(at)]);
    frame(ctx, ctl, &h, vec![click(at, true)]);
    frame(ctx, ctl, &h, vec![click(at, false)]);
}

#[test]
fn the_panel_shows_the_frames_numbers_controls_elements_and_cameras() {
    let ctx = egui::Context::default();
    let mut ctl = crate::testutil::controls();
    ctl.render.shading.auto_exposure = true;
    let mut history = History::default();
    for i in 0..300 {
        history.push(10.0 + f64::from(i % 7), 3.0);
    }
    assert_eq!(history.frame_ms.len(), HISTORY_FRAMES);
    // The first pass sizes the window; the second draws it.
    let first = frame(&ctx, &mut ctl, &history, vec![]);
    assert!(
        !first.textures_delta.set.is_empty(),
        "egui's font atlas is uploaded with the first frame"
    );
    let out = frame(&ctx, &mut ctl, &history, vec![]);
    let all: Vec<String> = texts(&out.shapes).into_iter().map(|t| t.0).collect();
    let joined = all.join("\n");
    for want in [
        "motu view",
        "64×36  pipeline  shaded",
        "frame 12.5 ms  gpu 3.25 ms  2.00 Mrays/s  1.00 traces/ray",
        "VRAM 1.0 MiB / 2.0 MiB",
        "structures 3/7 resident",
        "streaming: 4 passes, 5 built, 2 evicted",
        "samples 16  denoiser off",
        "bounces",
        "LOD auto",
        "auto exposure",
        "-1.50 EV",
        "x",
        "y",
        "1 a",
        "2 b",
    ] {
        assert!(all.iter().any(|t| t == want), "no {want:?} in:\n{joined}");
    }
    // The time graph is a line per series.
    let lines = out
        .shapes
        .iter()
        .filter(|c| matches!(&c.shape, Shape::Path(p) if p.points.len() == HISTORY_FRAMES))
        .count();
    assert_eq!(lines, 2, "frame and GPU time lines");
    let primitives = ctx.tessellate(out.shapes, out.pixels_per_point);
    assert!(primitives.iter().any(|p| match &p.primitive {
        egui::epaint::Primitive::Mesh(m) => !m.indices.is_empty(),
        _ => false,
    }));
}

#[test]
fn clicks_on_the_panel_toggle_elements_views_and_move_the_camera() {
    let ctx = egui::Context::default();
    let mut ctl = crate::testutil::controls();
    let h = History::default();
    frame(&ctx, &mut ctl, &h, vec![]);
    let out = frame(&ctx, &mut ctl, &h, vec![]);
    click_text(&ctx, &mut ctl, &out.shapes, "x");
    assert_eq!(ctl.elements_on, [false, true], "{}", ctl.message);
    // A click leaves the keyboard to the camera keys (no text field took it).
    assert!(!ctx.wants_keyboard_input());
    // The last element on stays on, as with the keys.
    let out = frame(&ctx, &mut ctl, &h, vec![]);
    click_text(&ctx, &mut ctl, &out.shapes, "y");
    assert_eq!(ctl.elements_on, [false, true]);
    let out = frame(&ctx, &mut ctl, &h, vec![]);
    click_text(&ctx, &mut ctl, &out.shapes, "all on");
    assert_eq!(ctl.elements_on, [true, true]);
    let out = frame(&ctx, &mut ctl, &h, vec![]);
    click_text(&ctx, &mut ctl, &out.shapes, "2 b");
    assert_eq!(ctl.fly.pose, crate::testutil::pose(2.0));
    let out = frame(&ctx, &mut ctl, &h, vec![]);
    click_text(&ctx, &mut ctl, &out.shapes, "heatmap");
    assert_eq!(ctl.render.view, View::Heatmap);
    let out = frame(&ctx, &mut ctl, &h, vec![]);
    click_text(&ctx, &mut ctl, &out.shapes, "albedo");
    assert_eq!(ctl.render.view, View::Albedo);
    let out = frame(&ctx, &mut ctl, &h, vec![]);
    click_text(&ctx, &mut ctl, &out.shapes, "shadows");
    assert!(!ctl.render.shadows);
}

#[test]
fn a_streaming_budget_that_holds_the_scene_says_the_full_build_draws_it() {
    let ctx = egui::Context::default();
    let mut ctl = crate::testutil::controls();
    let h = History::default();
    let mut i = info();
    i.stats.streaming = None;
    i.stats.stream_fit = Some(motu_render::stats::StreamFitStats {
        budget_bytes: 8 << 20,
        full_build_upper_bytes: 3 << 20,
        full_build: true,
        check_ms: 1.0,
    });
    let mut shown = |i: &PanelInfo| {
        let _ = ctx.run(input(vec![]), |c| build(c, i, &h, &mut ctl));
        let out = ctx.run(input(vec![]), |c| build(c, i, &h, &mut ctl));
        texts(&out.shapes)
            .into_iter()
            .map(|t| t.0)
            .collect::<Vec<_>>()
    };
    let all = shown(&i);
    let want = "full build: the budget holds the scene (at most 3.0 MiB)";
    assert!(all.iter().any(|t| t == want), "no {want:?} in {all:?}");
    // Refused (or not holding it): a plain full build is not claimed to be a hand-over.
    i.stats.stream_fit.as_mut().unwrap().full_build = false;
    let all = shown(&i);
    assert!(
        all.iter().any(|t| t == "full build (no streaming)"),
        "{all:?}"
    );
}

#[test]
fn a_refining_frame_names_its_stale_tlas_pieces() {
    let ctx = egui::Context::default();
    let mut ctl = crate::testutil::controls();
    let h = History::default();
    let mut i = info();
    i.stats.incomplete_pixels = 10;
    i.stats.tlas_pieces_stale = 3;
    let _ = ctx.run(input(vec![]), |c| build(c, &i, &h, &mut ctl));
    let out = ctx.run(input(vec![]), |c| build(c, &i, &h, &mut ctl));
    let all: Vec<String> = texts(&out.shapes).into_iter().map(|t| t.0).collect();
    let want = "streaming: 4 passes, 5 built, 2 evicted, 10 px refining, 3 TLAS pieces stale";
    assert!(all.iter().any(|t| t == want), "no {want:?} in {all:?}");
}
