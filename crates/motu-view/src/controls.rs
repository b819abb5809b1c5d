//! What the keys (and the panel's widgets) change: the next frame's options, the camera, the
//! element set, the panel, progressive accumulation and the denoiser.

use crate::{FlyCamera, ViewOptions};
use motu_abi::camera::CameraPose;
use motu_gpu::{RenderOptions, View};
use winit::keyboard::KeyCode;

/// The views `V` cycles through, in order (F1–F5 pick one; the panel offers them all).
pub(crate) const VIEWS: [View; 5] = [
    View::Shaded,
    View::Ids,
    View::Lod,
    View::Heatmap,
    View::Albedo,
];

/// A view's name on the panel.
pub(crate) fn view_name(v: View) -> &'static str {
    match v {
        View::Shaded => "shaded",
        View::Ids => "ids",
        View::Lod => "lod",
        View::Heatmap => "heatmap",
        View::Albedo => "albedo",
    }
}

/// Movement keys held down.
#[derive(Clone, Copy, Debug, Default)]
pub struct Keys {
    pub(crate) forward: bool,
    pub(crate) back: bool,
    pub(crate) left: bool,
    pub(crate) right: bool,
    pub(crate) up: bool,
    pub(crate) down: bool,
}

/// What the keys and the panel change: the next frame's options, the camera, the element set,
/// the panel, accumulation and the denoiser.
#[derive(Debug)]
pub struct Controls {
    pub render: RenderOptions,
    /// Accumulate samples while nothing changes (P).
    pub accumulate: bool,
    /// Filter the shown image (N; never the AOV).
    pub denoise: bool,
    /// Instance-level LOD wanted (M); the source reports what ran.
    pub lod_instance: bool,
    /// The panel is shown (Tab).
    pub panel: bool,
    pub elements: Vec<String>,
    pub elements_on: Vec<bool>,
    pub cameras: Vec<(String, CameraPose)>,
    pub fly: FlyCamera,
    pub keys: Keys,
    /// The last action, for the panel.
    pub message: String,
}

impl Controls {
    pub fn new(opts: &ViewOptions) -> Controls {
        Controls {
            render: opts.render,
            accumulate: opts.accumulate,
            denoise: opts.denoise,
            lod_instance: opts.lod_instance,
            panel: opts.panel,
            elements: opts.elements.clone(),
            elements_on: opts.elements_on.clone(),
            cameras: opts.cameras.clone(),
            fly: FlyCamera::new(opts.start, opts.speed),
            keys: Keys::default(),
            message: String::new(),
        }
    }

    /// Applies a key press or release; true when the key asks to quit.
    pub fn key(&mut self, code: KeyCode, pressed: bool, shift: bool) -> bool {
        let k = &mut self.keys;
        match code {
            KeyCode::KeyW => k.forward = pressed,
            KeyCode::KeyS => k.back = pressed,
            KeyCode::KeyA => k.left = pressed,
            KeyCode::KeyD => k.right = pressed,
            KeyCode::KeyE => k.up = pressed,
            KeyCode::KeyQ => k.down = pressed,
            _ => {}
        }
        if !pressed {
            return false;
        }
        let r = &mut self.render;
        let digit = match code {
            KeyCode::Digit1 => Some(0),
            KeyCode::Digit2 => Some(1),
            KeyCode::Digit3 => Some(2),
            KeyCode::Digit4 => Some(3),
            KeyCode::Digit5 => Some(4),
            KeyCode::Digit6 => Some(5),
            KeyCode::Digit7 => Some(6),
            KeyCode::Digit8 => Some(7),
            KeyCode::Digit9 => Some(8),
            KeyCode::Digit0 => Some(usize::MAX),
            _ => None,
        };
        match code {
            KeyCode::Escape => return true,
            KeyCode::KeyV => {
                let i = VIEWS.iter().position(|v| *v == r.view).unwrap_or(0);
                r.view = VIEWS[(i + 1) % VIEWS.len()];
            }
            KeyCode::F1 => r.view = View::Shaded,
            KeyCode::F2 => r.view = View::Ids,
            KeyCode::F3 => r.view = View::Lod,
            KeyCode::F4 => r.view = View::Heatmap,
            KeyCode::F5 => r.view = View::Albedo,
            KeyCode::KeyL => {
                // auto → 0 → 1 → … → 7 → auto
                r.lod.forced_lod = match r.lod.forced_lod {
                    f if f < 0 => 0,
                    f if f >= 7 => motu_abi::lod::LOD_NOT_FORCED,
                    f => f + 1,
                };
            }
            KeyCode::KeyK => r.lod.stochastic ^= 1,
            KeyCode::KeyM => self.lod_instance = !self.lod_instance,
            KeyCode::KeyH => r.shadows = !r.shadows,
            KeyCode::Tab => self.panel = !self.panel,
            KeyCode::KeyP => {
                self.accumulate = !self.accumulate;
                self.message = format!("accumulation {}", on_off(self.accumulate));
            }
            KeyCode::KeyN => {
                self.denoise = !self.denoise;
                self.message = format!("denoiser {}", on_off(self.denoise));
            }
            _ => {}
        }
        if let Some(d) = digit {
            if shift {
                self.toggle_element(d);
            } else {
                self.select_camera(d);
            }
        }
        false
    }

    /// Moves to the scene's camera `i` (nothing if there is none).
    pub fn select_camera(&mut self, i: usize) {
        if let Some((name, pose)) = self.cameras.get(i) {
            self.fly.pose = *pose;
            self.message = format!("camera {name}");
        }
    }

    /// Toggles element `d` (`usize::MAX`: all on); the last element on stays on.
    pub fn toggle_element(&mut self, d: usize) {
        let on = &mut self.elements_on;
        if d == usize::MAX {
            on.iter_mut().for_each(|e| *e = true);
            self.message = "all elements on".into();
            return;
        }
        if d >= on.len() {
            return;
        }
        if on[d] && on.iter().filter(|e| **e).count() == 1 {
            self.message = "the last element stays on".into();
            return;
        }
        on[d] = !on[d];
        self.message = format!(
            "element {} {}",
            self.elements[d],
            if on[d] { "on" } else { "off" }
        );
    }
}

fn on_off(b: bool) -> &'static str {
    if b {
        "on"
    } else {
        "off"
    }
}

#[cfg(test)]
mod tests;
