//! The viewer's panel: an egui window over the shown frame with the frame's numbers (frame
//! and GPU time graph, VRAM used/budget, resident structures, streaming passes, samples) and
//! controls (view, LOD, bounces, exposure, toggles, elements by name, the scene's cameras).
//!
//! [`build`] lays it out on an [`egui::Context`] from a [`PanelInfo`] and applies what the
//! user changed to [`Controls`] (the next frame's options), the same state the keys change.
//! The presenter draws egui's output after the screenshot's read-back: `--screenshot` and
//! `--aov` never contain it.

use std::collections::VecDeque;

use egui::{Color32, RichText, Ui};

use crate::controls::{view_name, VIEWS};
use crate::Controls;

/// Frames the time graph keeps.
pub const HISTORY_FRAMES: usize = 240;

/// The last frames' times for the graph.
#[derive(Clone, Debug, Default)]
pub struct History {
    /// Wall-clock milliseconds per shown frame (render + present).
    pub frame_ms: VecDeque<f32>,
    /// The renderer's GPU milliseconds per frame.
    pub gpu_ms: VecDeque<f32>,
}

impl History {
    pub fn push(&mut self, frame_ms: f64, gpu_ms: f64) {
        for (q, v) in [(&mut self.frame_ms, frame_ms), (&mut self.gpu_ms, gpu_ms)] {
            if q.len() == HISTORY_FRAMES {
                q.pop_front();
            }
            q.push_back(v as f32);
        }
    }
}

/// What the panel shows about the last frame.
#[derive(Clone, Debug, Default)]
pub struct PanelInfo {
    pub width: u32,
    pub height: u32,
    pub backend: &'static str,
    pub frame_ms: f64,
    pub gpu_ms: f64,
    pub rays_per_second: f64,
    pub traces_per_ray: f64,
    /// The exposure the frame was tone-mapped with (auto or fixed), stops.
    pub exposure_ev: f32,
    pub stats: crate::SourceStats,
    /// Samples per pixel in the shown image (accumulated at rest).
    pub samples: u32,
    pub denoised: bool,
}

pub(crate) fn mib(b: u64) -> String {
    if b >= 1 << 30 {
        format!("{:.2} GiB", b as f64 / (1u64 << 30) as f64)
    } else {
        format!("{:.1} MiB", b as f64 / (1u64 << 20) as f64)
    }
}

/// Lays the panel out for this frame; changes go to `ctl` (applied from the next frame).
pub fn build(ctx: &egui::Context, info: &PanelInfo, history: &History, ctl: &mut Controls) {
    egui::Window::new("motu view")
        .default_pos([8.0, 8.0])
        .default_width(300.0)
        .resizable(false)
        .show(ctx, |ui| {
            // A window shorter than the panel scrolls it.
            egui::ScrollArea::vertical()
                .id_salt("panel")
                .show(ui, |ui| contents(ui, info, history, ctl));
        });
}

/// The keys, as the panel's last line reminds them.
const KEYS: &str = "WASD/QE move, drag look, wheel speed, 1-9 cameras, Shift+1-9 elements, \
                    V/F1-F5 view, L lod, M lod mode, K dither, H shadows, P accumulate, \
                    N denoise, Tab panel, Esc quit";

fn contents(ui: &mut Ui, info: &PanelInfo, history: &History, ctl: &mut Controls) {
    ui.label(format!(
        "{}×{}  {}  {}",
        info.width,
        info.height,
        info.backend,
        view_name(ctl.render.view)
    ));
    timings(ui, info, history);
    memory(ui, info);
    ui.separator();
    render_controls(ui, info, ctl);
    ui.separator();
    elements(ui, ctl);
    cameras(ui, ctl);
    if !ctl.message.is_empty() {
        ui.label(RichText::new(&ctl.message).italics());
    }
    ui.label(RichText::new(KEYS).small().weak());
}

fn timings(ui: &mut Ui, info: &PanelInfo, history: &History) {
    ui.label(format!(
        "frame {:.1} ms  gpu {:.2} ms  {:.2} Mrays/s  {:.2} traces/ray",
        info.frame_ms,
        info.gpu_ms,
        info.rays_per_second / 1e6,
        info.traces_per_ray
    ));
    let (rect, _) =
        ui.allocate_exact_size(egui::vec2(ui.available_width(), 48.0), egui::Sense::hover());
    let painter = ui.painter_at(rect);
    painter.rect_filled(rect, 2.0, Color32::from_black_alpha(120));
    let max = history
        .frame_ms
        .iter()
        .chain(&history.gpu_ms)
        .copied()
        .fold(1.0f32, f32::max);
    let line = |q: &VecDeque<f32>, colour: Color32| {
        let n = q.len().max(2) as f32 - 1.0;
        let points: Vec<egui::Pos2> = q
            .iter()
            .enumerate()
            .map(|(i, v)| {
                egui::pos2(
                    rect.left() + rect.width() * i as f32 / n,
                    rect.bottom() - rect.height() * (v / max).clamp(0.0, 1.0),
                )
            })
            .collect();
        if points.len() >= 2 {
            painter.add(egui::Shape::line(points, egui::Stroke::new(1.0, colour)));
        }
    };
    line(&history.frame_ms, Color32::from_rgb(240, 200, 80));
    line(&history.gpu_ms, Color32::from_rgb(90, 200, 250));
    painter.text(
        rect.left_top() + egui::vec2(4.0, 2.0),
        egui::Align2::LEFT_TOP,
        format!("{max:.1} ms  (frame: yellow, gpu: blue)"),
        egui::FontId::proportional(10.0),
        Color32::LIGHT_GRAY,
    );
}

fn memory(ui: &mut Ui, info: &PanelInfo) {
    let s = &info.stats;
    let unbounded = s.vram_budget_bytes == 0 || s.vram_budget_bytes == u64::MAX;
    let budget = if unbounded {
        "device".to_string()
    } else {
        mib(s.vram_budget_bytes)
    };
    let fraction = if unbounded {
        0.0
    } else {
        (s.vram_used_bytes as f64 / s.vram_budget_bytes as f64) as f32
    };
    ui.add(
        egui::ProgressBar::new(fraction.clamp(0.0, 1.0))
            .text(format!("VRAM {} / {budget}", mib(s.vram_used_bytes))),
    );
    ui.label(format!(
        "structures {}/{} resident",
        s.resident_structures, s.total_structures
    ));
    ui.label(match s.streaming {
        Some((built, evicted)) => format!(
            "streaming: {} passes, {built} built, {evicted} evicted{}{}",
            s.passes,
            if s.incomplete_pixels > 0 {
                format!(", {} px refining", s.incomplete_pixels)
            } else {
                String::new()
            },
            if s.tlas_pieces_stale > 0 {
                format!(", {} TLAS pieces stale", s.tlas_pieces_stale)
            } else {
                String::new()
            }
        ),
        None => match &s.stream_fit {
            Some(f) if f.full_build => format!(
                "full build: the budget holds the scene (at most {})",
                mib(f.full_build_upper_bytes)
            ),
            _ => "full build (no streaming)".into(),
        },
    });
    ui.label(format!(
        "samples {}{}  denoiser {}",
        info.samples,
        if info.denoised { " (denoised)" } else { "" },
        if info.denoised { "on" } else { "off" }
    ));
}

fn render_controls(ui: &mut Ui, info: &PanelInfo, ctl: &mut Controls) {
    let r = &mut ctl.render;
    ui.horizontal_wrapped(|ui| {
        ui.label("view");
        for v in VIEWS {
            ui.selectable_value(&mut r.view, v, view_name(v));
        }
    });
    ui.horizontal(|ui| {
        let mut auto = r.lod.forced_lod < 0;
        if ui.checkbox(&mut auto, "LOD auto").changed() {
            r.lod.forced_lod = if auto {
                motu_abi::lod::LOD_NOT_FORCED
            } else {
                0
            };
        }
        if !auto {
            ui.add(egui::Slider::new(&mut r.lod.forced_lod, 0..=7).text("level"));
        }
    });
    ui.horizontal(|ui| {
        let mut dither = r.lod.stochastic != 0;
        if ui.checkbox(&mut dither, "dither").changed() {
            r.lod.stochastic = u32::from(dither);
        }
        ui.checkbox(&mut ctl.lod_instance, "instance LOD");
        ui.label(
            RichText::new(match info.stats.lod_mode {
                "" => "(mode ?)",
                "instance" => "(ran: instance)",
                "none" => "(no selectors)",
                _ => "(ran: traversal)",
            })
            .weak(),
        );
    });
    ui.add(egui::Slider::new(&mut r.shading.bounces, 0..=8).text("bounces"));
    ui.horizontal(|ui| {
        ui.checkbox(&mut r.shading.auto_exposure, "auto exposure");
        if r.shading.auto_exposure {
            ui.label(format!("{:+.2} EV", info.exposure_ev));
        } else {
            ui.add(egui::Slider::new(&mut r.shading.exposure_ev, -12.0..=12.0).text("EV"));
        }
    });
    ui.horizontal(|ui| {
        ui.checkbox(&mut r.shadows, "shadows");
        ui.checkbox(&mut ctl.accumulate, "accumulate");
        ui.checkbox(&mut ctl.denoise, "denoise");
    });
}

fn elements(ui: &mut Ui, ctl: &mut Controls) {
    if ctl.elements.is_empty() {
        return;
    }
    ui.label("elements");
    let mut toggled = None;
    egui::ScrollArea::vertical()
        .id_salt("elements")
        .max_height(160.0)
        .show(ui, |ui| {
            for (i, name) in ctl.elements.iter().enumerate() {
                let mut on = ctl.elements_on[i];
                if ui.checkbox(&mut on, name).changed() {
                    toggled = Some(i);
                }
            }
            if ui.small_button("all on").clicked() {
                toggled = Some(usize::MAX);
            }
        });
    if let Some(i) = toggled {
        // The keys' rule: the last element stays on.
        ctl.toggle_element(i);
    }
}

fn cameras(ui: &mut Ui, ctl: &mut Controls) {
    if ctl.cameras.is_empty() {
        return;
    }
    ui.label("cameras");
    let mut chosen = None;
    ui.horizontal_wrapped(|ui| {
        for (i, (name, _)) in ctl.cameras.iter().enumerate() {
            if ui.button(format!("{} {name}", i + 1)).clicked() {
                chosen = Some(i);
            }
        }
    });
    if let Some(i) = chosen {
        ctl.select_camera(i);
    }
}

#[cfg(test)]
mod tests;
