use motu_gpu::View;
use winit::keyboard::KeyCode;

use super::*;
use crate::testutil::{controls, pose};

fn press(c: &mut Controls, code: KeyCode, shift: bool) -> bool {
    let quit = c.key(code, true, shift);
    c.key(code, false, shift);
    quit
}

#[test]
fn keys_switch_views_lod_cameras_elements_and_panel() {
    let mut c = controls();
    press(&mut c, KeyCode::KeyV, false);
    assert_eq!(c.render.view, View::Ids);
    press(&mut c, KeyCode::F4, false);
    assert_eq!(c.render.view, View::Heatmap);
    // The albedo view (the denoiser's guide) follows the heatmap in the cycle, and is F5.
    press(&mut c, KeyCode::KeyV, false);
    assert_eq!(c.render.view, View::Albedo);
    press(&mut c, KeyCode::KeyV, false);
    assert_eq!(c.render.view, View::Shaded);
    press(&mut c, KeyCode::F5, false);
    assert_eq!(c.render.view, View::Albedo);
    press(&mut c, KeyCode::F1, false);
    assert_eq!(c.render.view, View::Shaded);
    // LOD: auto → 0 → 1 … → 7 → auto.
    assert!(c.render.lod.forced_lod < 0);
    press(&mut c, KeyCode::KeyL, false);
    assert_eq!(c.render.lod.forced_lod, 0);
    for _ in 0..7 {
        press(&mut c, KeyCode::KeyL, false);
    }
    assert_eq!(c.render.lod.forced_lod, 7);
    press(&mut c, KeyCode::KeyL, false);
    assert!(c.render.lod.forced_lod < 0);
    // LOD mode: instance ↔ traversal.
    assert!(c.lod_instance);
    press(&mut c, KeyCode::KeyM, false);
    assert!(!c.lod_instance);
    press(&mut c, KeyCode::KeyM, false);
    assert!(c.lod_instance);
    // Cameras on digits; a missing one changes nothing.
    press(&mut c, KeyCode::Digit2, false);
    assert_eq!(c.fly.pose, pose(2.0));
    press(&mut c, KeyCode::Digit9, false);
    assert_eq!(c.fly.pose, pose(2.0));
    // Elements on Shift+digits; the last one stays on; Shift+0 turns all on.
    press(&mut c, KeyCode::Digit1, true);
    assert_eq!(c.elements_on, [false, true]);
    press(&mut c, KeyCode::Digit2, true);
    assert_eq!(c.elements_on, [false, true], "{}", c.message);
    press(&mut c, KeyCode::Digit0, true);
    assert_eq!(c.elements_on, [true, true]);
    assert_eq!(c.fly.pose, pose(2.0), "Shift+digit is not a camera");
    press(&mut c, KeyCode::Tab, false);
    assert!(!c.panel);
    press(&mut c, KeyCode::KeyH, false);
    assert!(!c.render.shadows);
    assert!(press(&mut c, KeyCode::Escape, false));
}

#[test]
fn movement_keys_hold_until_released() {
    let mut c = controls();
    c.key(KeyCode::KeyW, true, false);
    c.key(KeyCode::KeyE, true, false);
    assert!(c.keys.forward && c.keys.up);
    c.key(KeyCode::KeyW, false, false);
    assert!(!c.keys.forward && c.keys.up);
}
