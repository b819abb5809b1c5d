use super::*;
use crate::panel::{build, History, PanelInfo};

fn pass(ctx: &egui::Context, ctl: &mut crate::Controls, script: &mut PanelScript, frame: u32) {
    let mut input = egui::RawInput {
        screen_rect: Some(egui::Rect::from_min_size(
            egui::Pos2::ZERO,
            egui::vec2(400.0, 700.0),
        )),
        ..Default::default()
    };
    script.inject(frame, &mut input).unwrap();
    let info = PanelInfo::default();
    let out = ctx.run(input, |ctx| build(ctx, &info, &History::default(), ctl));
    script.observe(&out.shapes);
}

#[test]
fn clicks_parse_and_reject_what_cannot_be_played() {
    assert_eq!(
        "3:shadows".parse::<PanelClick>(),
        Ok(PanelClick {
            frame: 3,
            label: "shadows".into()
        })
    );
    assert_eq!(
        "2:a:b".parse::<PanelClick>().map(|c| c.label),
        Ok("a:b".to_string())
    );
    for bad in ["shadows", "x:shadows", "0:shadows", "1:shadows", "2:"] {
        let e = bad.parse::<PanelClick>().unwrap_err();
        assert!(e.contains("--panel-click"), "{e}");
    }
}

/// A scripted click goes through egui like a user's: the element's checkbox, then the view's
/// button change the controls, from the frame after the release.
#[test]
fn a_scripted_click_changes_the_controls_like_a_users() {
    let ctx = egui::Context::default();
    let mut ctl = crate::testutil::controls();
    let mut script = PanelScript::new(&[
        "2:x".parse().unwrap(),
        "5:ids".parse().unwrap(),
        "9:nope".parse().unwrap(),
    ]);
    // egui sizes its window in the first pass: the second lays the texts out to click.
    pass(&ctx, &mut ctl, &mut script, 0);
    pass(&ctx, &mut ctl, &mut script, 1);
    for frame in 2..=4 {
        assert_eq!(ctl.elements_on, [true, true], "frame {frame}");
        pass(&ctx, &mut ctl, &mut script, frame);
    }
    assert_eq!(ctl.elements_on, [false, true], "{}", ctl.message);
    assert_eq!(ctl.render.view, motu_gpu::View::Shaded);
    for frame in 5..=7 {
        pass(&ctx, &mut ctl, &mut script, frame);
    }
    assert_eq!(ctl.render.view, motu_gpu::View::Ids);
    assert!(!script.is_empty());
    assert!(script.unplayed().unwrap().contains("9:nope"));
    // A label the panel does not show is an error naming it.
    let mut input = egui::RawInput::default();
    let e = script.inject(9, &mut input).unwrap_err();
    assert!(e.contains("\"nope\"") && e.contains("shadows"), "{e}");
}
