//! Scripted clicks on the panel (`motu view --panel-click FRAME:LABEL`): a scripted run cannot
//! click a real window, so the panel's input gets synthetic pointer events instead, at the
//! widget whose text is LABEL as the panel laid it out in the previous frame. The events go
//! through egui exactly as a user's would (hover, press, release over three frames) and change
//! the [`crate::Controls`] the next frame renders with: the end-to-end path of a click.

use egui::epaint::{ClippedShape, Shape};

/// One click: the widget whose text is `label`, starting at the panel pass of frame `frame`
/// (0-based, ≥ 2: egui sizes the panel in frame 0 and lays it out in frame 1; the pointer moves
/// over it then, presses a frame later and releases the frame after, so the change renders
/// from frame `frame + 3`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PanelClick {
    pub frame: u32,
    pub label: String,
}

impl std::str::FromStr for PanelClick {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let (frame, label) = s
            .split_once(':')
            .ok_or_else(|| format!("--panel-click {s:?}: expected FRAME:LABEL, e.g. 1:shadows"))?;
        let frame = frame.trim().parse::<u32>().map_err(|e| {
            format!("--panel-click {s:?}: the frame {frame:?} is not a frame number ({e})")
        })?;
        if frame < 2 {
            return Err(format!(
                "--panel-click {s:?}: egui sizes the panel in frame 0 and lays it out in frame 1; \
                 the first frame a click can start is 2"
            ));
        }
        if label.is_empty() {
            return Err(format!("--panel-click {s:?}: the label is empty"));
        }
        Ok(Self {
            frame,
            label: label.to_string(),
        })
    }
}

/// The clicks still to play and what the panel showed last (its texts and where).
#[derive(Debug, Default)]
pub(crate) struct PanelScript {
    clicks: Vec<PanelClick>,
    /// The previous panel pass's texts with their screen rectangles (clipped to what shows).
    texts: Vec<(String, egui::Rect)>,
    /// The click under way: its position, the frame it started and its label.
    active: Option<(egui::Pos2, u32, String)>,
    /// The input time of the click's press (seconds).
    press_time: Option<f64>,
}

impl PanelScript {
    pub(crate) fn new(clicks: &[PanelClick]) -> Self {
        Self {
            clicks: clicks.to_vec(),
            ..Self::default()
        }
    }

    pub(crate) fn is_empty(&self) -> bool {
        self.clicks.is_empty() && self.active.is_none()
    }

    /// Adds frame `frame`'s synthetic events to the panel's input. An error names a label not
    /// visible in the panel (a scripted run must not pass without its click).
    pub(crate) fn inject(&mut self, frame: u32, input: &mut egui::RawInput) -> Result<(), String> {
        if let Some(i) = self.clicks.iter().position(|c| c.frame == frame) {
            if self.active.is_some() {
                return Err(format!(
                    "--panel-click {frame}:{}: starts while the click before it is under way \
                     (a click takes 3 frames)",
                    self.clicks[i].label
                ));
            }
            let c = self.clicks.remove(i);
            let at = self
                .texts
                .iter()
                .find(|(t, _)| *t == c.label)
                .map(|(_, r)| r.center())
                .ok_or_else(|| {
                    let mut shown: Vec<&str> = self.texts.iter().map(|(t, _)| t.as_str()).collect();
                    shown.sort_unstable();
                    shown.dedup();
                    format!(
                        "--panel-click {}:{}: no widget labelled {:?} is visible in the panel \
                         at frame {frame} (shown: {shown:?}; is the window large enough, the \
                         panel on?)",
                        c.frame, c.label, c.label
                    )
                })?;
            tracing::info!(frame, label = %c.label, x = at.x, y = at.y, "scripted panel click");
            self.active = Some((at, frame, c.label));
        }
        if let Some((at, start, _)) = &self.active {
            let (at, step) = (*at, frame - start);
            input.events.push(egui::Event::PointerMoved(at));
            // egui counts a press and release as a click only within its click duration (0.8
            // s): slow frames (lavapipe) would make it a long press, so the release frame's
            // input is stamped just after the press (time stays monotonic: real time is later).
            match (step, input.time) {
                (1, t) => self.press_time = t,
                (2, Some(_)) => input.time = self.press_time.map(|t| t + 0.05),
                _ => {}
            }
            if step >= 1 {
                input.events.push(egui::Event::PointerButton {
                    pos: at,
                    button: egui::PointerButton::Primary,
                    pressed: step == 1,
                    modifiers: egui::Modifiers::NONE,
                });
            }
            if step >= 2 {
                self.active = None;
            }
        }
        Ok(())
    }

    /// Remembers where the panel pass just laid out its texts (only those inside their clip
    /// rectangle: a text scrolled or cut off cannot be clicked).
    pub(crate) fn observe(&mut self, shapes: &[ClippedShape]) {
        fn walk(s: &Shape, clip: egui::Rect, out: &mut Vec<(String, egui::Rect)>) {
            match s {
                Shape::Text(t) => {
                    let rect = t.galley.rect.translate(t.pos.to_vec2());
                    if clip.contains(rect.center()) {
                        out.push((t.galley.text().to_string(), rect));
                    }
                }
                Shape::Vec(v) => v.iter().for_each(|s| walk(s, clip, out)),
                _ => {}
            }
        }
        self.texts.clear();
        for c in shapes {
            walk(&c.shape, c.clip_rect, &mut self.texts);
        }
    }

    /// Clicks that never started (the run ended first): an error for a scripted run.
    pub(crate) fn unplayed(&self) -> Option<String> {
        let left: Vec<String> = self
            .clicks
            .iter()
            .map(|c| format!("{}:{}", c.frame, c.label))
            .chain(
                self.active
                    .iter()
                    .map(|(_, f, l)| format!("{f}:{l} (unfinished)")),
            )
            .collect();
        (!left.is_empty()).then(|| {
            format!(
                "--panel-click: the run ended before these clicks were played (a click needs \
                 its frame and 3 more; is the panel shown?): {}",
                left.join(", ")
            )
        })
    }
}

#[cfg(test)]
mod tests;
