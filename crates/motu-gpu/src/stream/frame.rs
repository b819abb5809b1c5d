//! One frame: trace pipeline and frame buffers, the passes, the prefetch, the statistics.

use motu_abi::camera::CameraParams;

use super::passes::guard_pixels;
use super::{FrameStreamStats, StreamingRenderer};
use crate::error::{GpuError, Result};
use crate::render::{frame_params, FrameMeasure, RenderOptions, RenderOutput, RenderStats, Tracer};

impl<'a> StreamingRenderer<'a> {
    /// Renders one frame: build–traverse passes until every pixel is complete (or
    /// `max_passes`), then a prefetch of what the guard band saw and, when the caller named
    /// the next frame's camera ([`Self::set_next_camera`]), what a probe of it met.
    /// `opts.frames` is ignored (one frame per call: a camera path calls this per frame).
    pub fn render_frame(
        &mut self,
        camera: &CameraParams,
        opts: &RenderOptions,
    ) -> Result<(RenderOutput, FrameStreamStats)> {
        if let Some(why) = &self.poisoned {
            return Err(GpuError::InvalidRequest(format!(
                "streaming renderer unusable after an earlier failure: {why}"
            )));
        }
        let (w, h) = (camera.width, camera.height);
        if w == 0 || h == 0 || w >= 1 << 15 || h >= 1 << 15 {
            return Err(GpuError::InvalidRequest(format!(
                "image size {w}×{h} is invalid for streaming (each side 1 to 32767)"
            )));
        }
        let span = tracing::info_span!(
            "stream_frame",
            frame = self.frame + 1,
            width = w,
            height = h
        );
        let _g = span.enter();
        let frame_t0 = std::time::Instant::now();
        self.frame += 1;
        self.frame_stats = FrameStreamStats {
            frame: self.frame,
            ..Default::default()
        };
        self.frame_first_stamp = self.stamp + 1;
        self.kept.step_start = None;
        let need_tracer =
            !matches!(&self.tracer, Some((b, s, _)) if *b == opts.backend && *s == opts.stack_size);
        if need_tracer {
            if let Some((_, _, t)) = self.tracer.take() {
                t.release(&mut self.heap);
            }
            self.pinned = vec![false; self.item_count()];
            let t = self
                .with_eviction_or_rebuilt_tlases(|s| {
                    // Streamed TLASes keep every PI in the hardware walk (no box lists).
                    let slots = crate::scene::pi_capacity(&s.view, false);
                    Tracer::new(&s.ctx.clone(), &mut s.heap, opts, slots, true)
                })
                .map_err(|e| self.skeleton_error("the trace pipeline", e))?;
            self.tracer = Some((opts.backend, opts.stack_size, t));
        }
        let pixels = u64::from(w) * u64::from(h);
        let guard = guard_pixels(w, h, self.opts.guard_band_px);
        let mut params = frame_params(camera, opts, self.view.root_tlas);
        params.shading = self.shading.address;
        self.pinned = vec![false; self.item_count()];
        let fb = self.frame_buffers(w, h, guard.len(), &params, &opts.shading)?;
        // Making room for the frame may have evicted BLASes that TLASes still reference.
        if !self.dirty.is_empty() {
            self.built_now.clear();
            if let Err(e) = self
                .rebuild_dirty()
                .and_then(|()| self.upload_tlas_addresses())
            {
                fb.release(&mut self.heap);
                self.quarantine_after_failure(&e);
                return Err(e);
            }
        }
        let next = self.next_camera.take();
        let result = self.run_passes(&fb, w, h, &guard).and_then(|out| {
            // The probe of the next frame's camera (its buffers are this frame's: same size).
            let probe = match next {
                Some(n)
                    if self.opts.probe_stride > 0
                        && (n.width, n.height) == (w, h)
                        && self.frame_stats.complete
                        && !self.frame_build_spent() =>
                {
                    Some((n, self.probe_next_camera(&fb, &n, opts, None, false)?))
                }
                _ => None,
            };
            Ok((out, probe))
        });
        let (out, probe) = match result {
            Ok(r) => r,
            Err(e) => {
                fb.release(&mut self.heap);
                return Err(e);
            }
        };
        self.keep_frame_buffers(fb, w, h, guard.len());
        let (records, rgba_words, counters, mut guard_demand) = out;
        // The working set of the frame's rays (before the prefetch builds for the next).
        let mut working_meshes = std::collections::BTreeSet::new();
        for (b, &f) in self.used_in_frame.iter().enumerate() {
            if f == self.frame {
                self.frame_stats.working_set_blases += 1;
                self.frame_stats.working_set_bytes += self.blas_bytes[b];
                working_meshes.extend(self.blas_meshes(b));
            }
        }
        // Of working_set_bytes: what the meshes take from the budget (0 in host memory).
        self.frame_stats.working_set_mesh_bytes = working_meshes
            .into_iter()
            .filter_map(|m| self.meshes[m].as_ref().map(|g| self.mesh_budget_bytes(g)))
            .sum();
        // Prefetch: what the guard band saw, evicting only what this frame did not see (what
        // does not fit is skipped), within what is left of the frame's build budget. With a
        // probe of the next camera, what its rays need comes first, and only what the probe
        // saw is kept: this frame is done, the next one is what the room is for.
        let mut again = None;
        let evictions_at_probe = self.evictions;
        if let Some((next, (p, open))) = probe {
            let needed = p.needed_ids();
            guard_demand.merge_first(p);
            self.frame_first_stamp = self.stamp;
            again = Some((next, open, needed));
        }
        if !guard_demand.is_empty() && self.frame_stats.complete && !self.frame_build_spent() {
            if let Err(e) = self
                .make_resident(&guard_demand, true)
                .and_then(|()| match again {
                    Some((next, open, needed)) => {
                        self.probe_again(&next, opts, open, needed, evictions_at_probe)
                    }
                    None => Ok(()),
                })
            {
                self.quarantine_after_failure(&e);
                return Err(e);
            }
        }
        // Pass marks (auto) for the next probes: this frame evicted for build room and its
        // prefetch built all it wanted.
        let st = &self.frame_stats;
        let build_room = st
            .evicted
            .saturating_sub(st.evicted_for_tlas + st.evicted_on_refusal);
        if super::PassMarks::auto_wanted(build_room, st.prefetch_skipped) {
            self.pass_marks_held = self.frame;
        }
        let report = self.heap.report();
        self.frame_stats.frame_ms = frame_t0.elapsed().as_secs_f64() * 1e3;
        let resident_textures = self.shading.resident_textures();
        let st = &mut self.frame_stats;
        st.resident_textures = resident_textures;
        // Resident bytes split once: streamed BLASes and their meshes (what the room is for)
        // beside the skeleton's BLASes and TLASes.
        let (mut streamed_blases, mut streamed_bytes, mut skeleton_bytes) = (0u32, 0u64, 0u64);
        for (a, &buildable) in self.blas.iter().zip(&self.buildable) {
            if let Some(a) = a {
                if buildable {
                    streamed_blases += 1;
                    streamed_bytes += a.size_bytes;
                } else {
                    skeleton_bytes += a.size_bytes;
                }
            }
        }
        for g in self.meshes.iter().flatten() {
            if self.meshes_budgeted {
                streamed_bytes += g.size_bytes();
            } else {
                st.resident_host_mesh_bytes += g.size_bytes();
            }
        }
        let host_counts = self.heap.host_visible_counts_against_budget();
        skeleton_bytes += self
            .tlas
            .iter()
            .flatten()
            .map(|t| t.size_bytes(host_counts))
            .sum::<u64>()
            + self.placeholders.bytes;
        st.resident_blases = streamed_blases;
        st.resident_tlases = self.tlas.iter().filter(|t| t.is_some()).count() as u32;
        st.resident_bytes = streamed_bytes + skeleton_bytes;
        st.vram_peak_bytes = report.peak_block_bytes;
        st.vram_budget_bytes = report.budget_bytes;
        st.heap_block_bytes = report.budget_block_bytes;
        st.heap_in_use_bytes = report.budget_in_use_bytes;
        let fixed_bytes = report.budget_in_use_bytes.saturating_sub(streamed_bytes);
        st.room_bytes = report.budget_bytes.saturating_sub(fixed_bytes);
        let tot = &mut self.totals;
        tot.frames += 1;
        tot.passes += u64::from(st.passes);
        tot.blas_built += u64::from(st.blas_built);
        tot.tlas_built += u64::from(st.tlas_built);
        tot.tlas_rebuilt += u64::from(st.tlas_rebuilt);
        tot.tlas_rebuild_groups += u64::from(st.tlas_rebuild_groups);
        tot.evicted += u64::from(st.evicted);
        tot.deferred += u64::from(st.deferred);
        tot.incomplete_frames += u64::from(!st.complete);
        tot.fallback_pixels += st.fallback_pixels;
        tot.bytes_streamed += st.bytes_streamed;
        tot.built_bytes += st.built_bytes;
        tot.restored_blases += u64::from(st.restored_blases);
        tot.restored_bytes += st.restored_bytes;
        tot.restore_ms += st.restore_ms;
        tot.rebuilt_blases += u64::from(st.rebuilt_blases);
        tot.rebuilt_bytes += st.rebuilt_bytes;
        tot.cache_stored += u64::from(st.cache_stored);
        tot.cache_stored_bytes += st.cache_stored_bytes;
        tot.cache_store_ms += st.cache_store_ms;
        tot.restore_gb_per_s = if tot.restore_ms > 0.0 {
            tot.restored_bytes as f64 / (tot.restore_ms * 1e6)
        } else {
            0.0
        };
        tot.triangles_built += st.triangles_built;
        tot.build_ms += st.build_ms;
        tot.vram_peak_bytes = report.peak_block_bytes;
        tot.host_mesh_peak_bytes = tot.host_mesh_peak_bytes.max(st.resident_host_mesh_bytes);

        let (aov, rgba8, heatmap_max, exposure_ev) =
            crate::render::frame_outputs(w, h, records, &rgba_words, opts);
        crate::render::check_texture_residency(&counters)?;
        self.frame_stats.truncated_rays = u64::from(counters[crate::render::STAT_TRUNCATED_RAYS]);
        let stats = RenderStats::measured(
            opts,
            FrameMeasure {
                width: w,
                height: h,
                frames: 1,
                ms_per_frame: self.frame_stats.trace_ms,
                primary_rays: pixels + self.frame_stats.reshot_pixels,
                aov: &aov,
                counters: &counters,
                heatmap_max,
                exposure_ev,
                as_bytes: self
                    .blas
                    .iter()
                    .flatten()
                    .map(|a| a.size_bytes)
                    .chain(self.tlas.iter().flatten().map(|t| t.accel.size_bytes))
                    .sum(),
                alloc: report,
                passes: self.frame_stats.passes,
            },
        );
        tracing::info!(
            frame = self.frame,
            passes = self.frame_stats.passes,
            blas_built = self.frame_stats.blas_built,
            evicted = self.frame_stats.evicted,
            "stream frame done"
        );
        Ok((RenderOutput { aov, rgba8, stats }, self.frame_stats.clone()))
    }

    /// Later probe rounds (`StreamOptions::probe_rounds`): the pixels `open` the round before
    /// left open are probed again against what the prefetch just built, and what they need is
    /// prefetched, while the prefetch built some structure a round's rays `needed` first (the
    /// open pixels' rays go on from there) and pixels stay open. Then verifying rounds
    /// (`StreamOptions::probe_verify_rounds`) over every pixel, unless the rounds settled
    /// (no pixel left open) and nothing was evicted since the first probe (`self.evictions`
    /// was `evictions_at_probe` then): the next frame then finds everything its rays need.
    fn probe_again(
        &mut self,
        next: &CameraParams,
        opts: &RenderOptions,
        mut open: Vec<u32>,
        mut needed: Vec<u32>,
        evictions_at_probe: u64,
    ) -> Result<()> {
        let mut settled = open.is_empty();
        while !open.is_empty()
            && self.frame_stats.probe_rounds < self.opts.probe_rounds
            && needed.iter().any(|&b| self.blas[b as usize].is_some())
            && !self.frame_build_spent()
        {
            let Some((demand, still_open)) = self.probe_round(next, opts, Some(&open))? else {
                return Ok(());
            };
            needed = demand.needed_ids();
            if needed.is_empty() {
                settled = true;
                break;
            }
            self.make_resident(&demand, true)?;
            open = still_open;
            settled = open.is_empty();
        }
        if settled && self.evictions == evictions_at_probe {
            return Ok(());
        }
        // Verifying rounds: the prefetch evicted, for room, structures no round met, and the
        // next frame's rays may pass through some of them; every pixel again finds those. A
        // round that built something leaves its open pixels' rays going on past it, so the
        // next round runs whether or not it evicted.
        while self.frame_stats.probe_verify_rounds < self.opts.probe_verify_rounds
            && !self.frame_build_spent()
        {
            self.frame_stats.probe_verify_rounds += 1;
            let Some((demand, _)) = self.probe_round(next, opts, None)? else {
                return Ok(());
            };
            if demand.needed_ids().is_empty() {
                break;
            }
            let built = self.frame_stats.prefetched;
            self.make_resident(&demand, true)?;
            if self.frame_stats.prefetched == built {
                break;
            }
        }
        Ok(())
    }

    /// One later probe round in the kept frame buffers: the pixels `again`, or (None) a
    /// verifying round over every pixel. None when no buffers are kept.
    fn probe_round(
        &mut self,
        next: &CameraParams,
        opts: &RenderOptions,
        again: Option<&[u32]>,
    ) -> Result<Option<(super::demand::Demand, Vec<u32>)>> {
        let Some((fb, w, h, g)) = self.take_kept_frame_buffers() else {
            return Ok(None);
        };
        let probed = self.probe_next_camera(&fb, next, opts, again, again.is_none());
        self.keep_frame_buffers(fb, w, h, g);
        probed.map(Some)
    }
}
