//! Progressive refinement while the camera rests: each frame of the shaded view draws the next
//! `spp` samples of every pixel's sequence (`Shading::first_sample`), and the viewer averages
//! the frames in linear light until anything changes (the camera, an option, the element set,
//! the window, or a streamed frame still refining), when it starts again from sample 0. The
//! first frame of a run is the image `motu render` writes; its AOV (the pixel centres) stays
//! the frame's AOV while later frames add samples.
//!
//! The frames come tone-mapped (8-bit sRGB at their own exposure): each is taken back to
//! linear with its exposure, summed in `f32`, and the mean tone-mapped again (auto exposure
//! over the mean, or the fixed EV). What a frame clipped (above 1 after its exposure) is lost
//! to the sum; 8-bit steps average out under the noise.

use motu_abi::aov::Aov;
use motu_abi::camera::CameraParams;
use motu_abi::shade::{exposure_ev_of_logs, log_luminance, srgb_to_linear, tone_map};
use motu_gpu::{RenderOptions, RenderOutput, View};
use rayon::prelude::*;

/// Samples a pixel accumulates at most (well inside the sequence's 2^20 sample indices); then
/// the image stays as it is until something changes.
pub const MAX_ACCUMULATED_SAMPLES: u32 = 1 << 16;

/// What an accumulation run was started for: a change of any of it starts again.
#[derive(Clone, Debug, PartialEq)]
struct RunKey {
    camera: CameraParams,
    opts: RenderOptions,
    elements_on: Vec<bool>,
    lod_instance: bool,
}

/// The running sum of a camera at rest.
#[derive(Debug, Default)]
pub struct Accumulator {
    key: Option<RunKey>,
    sum: Vec<[f32; 3]>,
    samples: u32,
    /// The run's first frame's AOV (sample 0: the pixel centres).
    aov: Option<Aov>,
}

impl Accumulator {
    /// Samples in the current run (0: none yet).
    pub fn samples(&self) -> u32 {
        self.samples
    }

    /// Forgets the run: the next frame starts at sample 0.
    pub fn reset(&mut self) {
        self.key = None;
        self.sum.clear();
        self.samples = 0;
        self.aov = None;
    }

    /// The first sample the next frame of `camera` with `opts` should draw: 0 after any
    /// change, else where the run stands. `None`: nothing accumulates (the view is not shaded).
    pub fn first_sample(
        &mut self,
        camera: &CameraParams,
        opts: &RenderOptions,
        elements_on: &[bool],
        lod_instance: bool,
    ) -> Option<u32> {
        if opts.view != View::Shaded {
            self.reset();
            return None;
        }
        let key = RunKey {
            camera: *camera,
            opts: *opts,
            elements_on: elements_on.to_vec(),
            lod_instance,
        };
        if self.key.as_ref() != Some(&key) {
            self.reset();
            self.key = Some(key);
        }
        Some(self.samples.min(MAX_ACCUMULATED_SAMPLES))
    }

    /// Adds `frame` (rendered from [`Accumulator::first_sample`] with `opts`) to the run and
    /// replaces its image with the run's mean and its AOV with the run's first; returns the
    /// run's samples.
    pub fn add(&mut self, frame: &mut RenderOutput, opts: &RenderOptions) -> u32 {
        let n = (frame.rgba8.len() / 4) as u32;
        if self.sum.len() != n as usize {
            self.sum = vec![[0.0; 3]; n as usize];
            self.samples = 0;
        }
        let spp = opts.shading.spp.max(1);
        // Per pixel independent, on rayon threads (sequentially ~40 ms of a 640×360 frame:
        // three `powf` each way and a `ln` a pixel); the log terms are summed in pixel order,
        // so the exposure is `auto_exposure_ev`'s to the bit.
        if self.samples < MAX_ACCUMULATED_SAMPLES {
            let inv = (-frame.stats.exposure_ev).exp2();
            let weight = spp as f32;
            let linear = srgb_lut();
            self.sum
                .par_iter_mut()
                .zip(frame.rgba8.par_chunks_exact(4))
                .for_each(|(s, p)| {
                    for (c, v) in s.iter_mut().zip(&p[..3]) {
                        *c += weight * linear[usize::from(*v)] * inv;
                    }
                });
            if self.samples == 0 {
                self.aov = Some(frame.aov.clone());
            }
            self.samples += spp;
        }
        let inv_n = 1.0 / self.samples as f32;
        let mean = |s: &[f32; 3]| s.map(|c| c * inv_n);
        let ev = if opts.shading.auto_exposure {
            let logs: Vec<Option<f64>> = self
                .sum
                .par_iter()
                .map(|s| log_luminance(mean(s)))
                .collect();
            exposure_ev_of_logs(logs.into_iter().flatten())
        } else {
            opts.shading.exposure_ev
        };
        let scale = ev.exp2();
        frame
            .rgba8
            .par_chunks_exact_mut(4)
            .zip(self.sum.par_iter())
            .for_each(|(p, s)| {
                p[..3].copy_from_slice(&tone_map(mean(s), scale));
                p[3] = 255;
            });
        frame.stats.exposure_ev = ev;
        if let Some(aov) = &self.aov {
            frame.aov.clone_from(aov);
        }
        self.samples
    }
}

/// `srgb_to_linear` of every 8-bit value, computed as the per-pixel loop did (`v / 255`).
fn srgb_lut() -> &'static [f32; 256] {
    static LUT: std::sync::OnceLock<[f32; 256]> = std::sync::OnceLock::new();
    LUT.get_or_init(|| std::array::from_fn(|v| srgb_to_linear(v as f32 / 255.0)))
}

/// Filters the shown image with the denoiser of `motu render --denoise` (never the AOV).
pub fn denoise(
    frame: &mut RenderOutput,
    camera: &CameraParams,
    base_colour: impl Fn(u32) -> [f32; 3],
) {
    use motu_render::denoise::{denoise_rgba8, guide_from_aov, pixel_footprint, DenoiseOptions};
    let guide = guide_from_aov(&frame.aov, camera, base_colour);
    denoise_rgba8(
        &mut frame.rgba8,
        frame.aov.width,
        frame.aov.height,
        &guide,
        pixel_footprint(camera),
        &DenoiseOptions::default(),
    );
}

#[cfg(test)]
mod tests;
