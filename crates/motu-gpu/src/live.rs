//! A renderer that keeps its pipeline and frame buffers between frames (`motu view`): the same
//! trace and outputs as [`crate::render`], without recompiling the pipeline or reallocating
//! per frame. Buffers are reallocated only when the image size changes.

use motu_abi::camera::CameraParams;

use crate::error::Result;
use crate::render::{
    alloc_frame, frame_outputs, frame_params, params_bytes, run_frames, write_params, Frame,
    FrameMeasure, FrameResult, RenderOptions, RenderOutput, RenderStats, Tracer,
};
use crate::scene::GpuScene;

/// Owns a built scene plus the trace pipeline and frame buffers of the last frame.
pub struct LiveRenderer {
    tracer: Option<(crate::Backend, u32, Tracer)>,
    frame: Option<(Frame, u32, u32)>,
    scene: GpuScene,
}

impl std::fmt::Debug for LiveRenderer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveRenderer")
            .field("size", &self.frame.as_ref().map(|f| (f.1, f.2)))
            .finish()
    }
}

impl LiveRenderer {
    pub fn new(scene: GpuScene) -> LiveRenderer {
        LiveRenderer {
            tracer: None,
            frame: None,
            scene,
        }
    }

    pub fn scene(&self) -> &GpuScene {
        &self.scene
    }

    /// Renders one frame (`opts.frames` is ignored: one per call). Outputs and statistics are
    /// those of [`crate::render`] for the same camera and options.
    pub fn render_frame(
        &mut self,
        camera: &CameraParams,
        opts: &RenderOptions,
    ) -> Result<RenderOutput> {
        let (w, h) = (camera.width, camera.height);
        if w == 0 || h == 0 || u64::from(w) * u64::from(h) > (1 << 28) {
            return Err(crate::GpuError::InvalidRequest(format!(
                "image size {w}×{h} is invalid"
            )));
        }
        let ctx = self.scene.context().clone();
        let params = frame_params(
            camera,
            opts,
            self.scene.root_tlas,
            self.scene.shading_address,
        );
        {
            let mut heap = self.scene.heap();
            if !matches!(&self.tracer, Some((b, s, _)) if *b == opts.backend && *s == opts.stack_size)
            {
                if let Some((_, _, t)) = self.tracer.take() {
                    t.release(&mut heap);
                }
                let t = Tracer::new(&ctx, &mut heap, opts, self.scene.pi_capacity, false, false)?;
                self.tracer = Some((opts.backend, opts.stack_size, t));
            }
            match &self.frame {
                Some((f, fw, fh))
                    if (*fw, *fh) == (w, h)
                        && f.params.size_bytes() >= params_bytes(&opts.shading) =>
                {
                    write_params(&f.params, &params, &opts.shading)?;
                }
                _ => {
                    if let Some((f, _, _)) = self.frame.take() {
                        f.release(&mut heap);
                    }
                    let pixels = u64::from(w) * u64::from(h);
                    self.frame = Some((
                        alloc_frame(&mut heap, pixels, &params, &opts.shading)?,
                        w,
                        h,
                    ));
                }
            }
        }
        let (Some((_, _, tracer)), Some((frame, _, _))) = (&self.tracer, &self.frame) else {
            return Err(crate::GpuError::InvalidRequest(
                "live renderer state".into(),
            ));
        };
        let FrameResult {
            records,
            rgba_words,
            counters,
            frame_ns,
        } = run_frames(&ctx, &self.scene, tracer, frame, w, h, 1)?;
        let (aov, rgba8, heatmap_max, exposure_ev) =
            frame_outputs(w, h, records, &rgba_words, opts);
        let ms = frame_ns.first().copied().unwrap_or(0.0) / 1e6;
        let pixels = u64::from(w) * u64::from(h);
        let stats = RenderStats::measured(
            opts,
            FrameMeasure {
                width: w,
                height: h,
                frames: 1,
                ms_per_frame: ms,
                primary_rays: pixels,
                aov: &aov,
                counters: &counters,
                heatmap_max,
                exposure_ev,
                as_bytes: self.scene.report().as_bytes,
                alloc: self.scene.alloc_report(),
                passes: 1,
            },
        );
        Ok(RenderOutput { aov, rgba8, stats })
    }
}

impl Drop for LiveRenderer {
    fn drop(&mut self) {
        let mut heap = self.scene.heap();
        if let Some((_, _, t)) = self.tracer.take() {
            t.release(&mut heap);
        }
        if let Some((f, _, _)) = self.frame.take() {
            f.release(&mut heap);
        }
    }
}
