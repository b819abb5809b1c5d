//! The prefetch probe: after a frame, when the caller knows the next frame's camera (a camera
//! path, a flight), one pass of that camera's pixels runs every ray a pixel traces (primary,
//! then the lights' shadow rays and the AO rays from the resident hit) against what is
//! resident, writing nothing but the stamps. What they meet and is not resident is prefetched;
//! what is resident and met is kept. The guard band sees only primary visibility just outside
//! the image; shadow and AO rays reach structures the camera never sees, and a moving camera's
//! new hit points send them elsewhere: without the probe each such frame needed a second pass.
//!
//! The probe also sees what its rays pass through. The hardware walks a resident triangle
//! BLAS with no callback unless a triangle is hit, so a BLAS that rays cross without hitting
//! looked unused, the prefetch evicted it for room, and the next frame's rays, entering its
//! boxes in front of their hits, had to open it again: most second passes at a quarter of the
//! full build were that. Each streamed TLAS therefore carries a *marks* BLAS beside its proxy:
//! the resident clusters' boxes, under an instance mask only probe rays' mark walks trace
//! (`CULL_MASK_MARKS`, `traverse.glsl`); a probe ray that stays open (a non-resident structure
//! lies in front of its resident hit) walks again over boxes only, up to that hit, and entering
//! a member's box and one of the boxes inside the BLAS (`proxy_boxes.rs`) marks the BLAS seen,
//! so the prefetch keeps it. Ordinary passes cull the marks with their mask and pay nothing
//! for them. Marking what *every* probe ray passed kept more resident than the next frames used
//! (more built, no fewer passes: BENCHMARKS.md, session 11).
//!
//! *Pass marks* (`StreamOptions::pass_marks`, `auto` by default) take the middle way: the
//! final rays of every N-th row walk the marks too, but what they pass is marked *passed*
//! (`4 × stamp - 1`), which refreshes the BLAS's LRU age to just below what the probe met
//! instead of keeping it. The prefetch then evicts the passed BLASes after everything else it
//! may evict and never skips a build for them. At a third of the full build (H200) the first
//! passes' misses were nearly all such BLASes, evicted by the prefetch because no probe ray
//! met them: whole rows (a launch's subgroups are runs of one row) of every 2nd row took the
//! passes after the first from 1.727 to 1.182 at about the same frame time; at half, fewer
//! passes but slower frames (the walk costs more than the second passes it saves).
//! BENCHMARKS.md, session 25. Hence `PassMarks::Auto`, the default: it marks only after
//! frames whose builds evicted for room while the prefetch skipped nothing (a third: from the
//! third frame on, 1.182 at the same frame time; half and a quarter: never; session 26).
//!
//! A probe ray stops at the first structure that is not resident (it requests it, then goes on
//! as if its resident hit were final). Once the prefetch built that structure, the ray may hit
//! in it, and its shadow and AO rays leave from there for structures no probe ray met, so the
//! next frame's first pass opened them. The probe lists the pixels some ray of which requested
//! a structure (`g_probe_open`, the pass's incomplete list); after the prefetch, a later round
//! probes only those pixels and prefetches what they need, while the prefetch built a
//! structure the round before needed first and pixels stay open
//! (`StreamOptions::probe_rounds`).
//!
//! The prefetch makes room by evicting what no probe ray met, least recently seen first, and
//! without pass marks on every row the structures the next frame's rays only pass through look
//! like any other: at a quarter of island 0.3's full build (H200, primary visibility) the next
//! frames' first passes missed 8–64 such structures each, and every frame took two passes
//! although what the frames need was 0.64–0.77 of the room. *Verifying rounds*
//! (`StreamOptions::probe_verify_rounds`) then probe every pixel again against what the
//! prefetch left resident and prefetch what is now missing (their sightings, need and marks
//! add to the first round's, so what any round met stays pinned): 1.909 → 1.091 passes after
//! the first there (BENCHMARKS.md, session 28). They are skipped when the rounds before left
//! no pixel open and nothing was evicted since the first probe.
//!
//! Every round that finds something costs a build step, and each step rebuilds every TLAS
//! piece holding an instance of what it built or evicted: with the root split into pieces and
//! popular BLASes instanced in all of them, every piece (a quarter of island 0.3 on the H100:
//! 43 rebuilds a frame, most after the probe's steps). Those rebuilds cannot wait for the end
//! of the probe: the next round's rays must meet what the step built (they go on from its
//! hits: that is what the round is for), and no TLAS may still reference what it evicted
//! (freed). Nor can the last step's wait for the next frame's first pass, which traces the
//! same TLASes. What can be saved is steps: with [`ProbeLater::Verify`](super::ProbeLater)
//! a first round whose prefetch evicted goes straight to the verifying rounds, which probe the
//! pixels it left open with every other, one step for both (lavapipe, the 0.002 island at a
//! quarter of its full build along the default path, nine root pieces, host memory counted
//! apart: TLAS rebuilds a frame 16.7 → 15.0, instance records 34.2k → 29.2k, 1.00 pass after
//! the first either way).
//!
//! With one diffuse bounce (the default shaded view) a pixel's path has two closest-hit links
//! (the primary ray, the bounce ray), each of which may meet a structure that is not resident
//! in front of its resident hit; the rounds above resolve one such link each. Measured on
//! lavapipe (island 0.002 and 0.02, 64×36 along palmsCam, 8 frames), the probe already reaches
//! the bounce vertices: at a sixteenth of the full build nearly every structure the next
//! frame's first pass misses is one some probe round met (0.002: 124 of 126 over the path;
//! 0.02: 153 of 160), the working set being about twice the room (23.8 MB in 11.6 MB), and at
//! an eighth and a quarter the frames take 1.00–1.14 passes after the first. More rounds
//! (`--stream-probe-rounds 3`: 3.71 → 4.00 passes at a sixteenth), fewer (`1`, verify `0`:
//! 4.29) and [`ProbePaths::Stop`](super::ProbePaths::Stop) (a round's open paths end at the
//! open link instead of going on from a resident hit behind it: 4.00) did not pay there;
//! `Stop` stays opt-in for a GPU to measure on island 0.3, where the ⅛ frames took 8.0 passes
//! with the bounce against 4.9 without.

use motu_abi::camera::CameraParams;

use super::buffers::FrameBuffers;
use super::demand::Demand;
use super::params::{passed_mark, probe_flags, REQUEST_CAMERA};
use super::passes::{pack_biased, relist, PassReadback, Sighting, LEVEL_NEEDED};
use super::StreamingRenderer;
use crate::error::Result;
use crate::render::{frame_params, RenderOptions};

/// What a probe round met that is not resident: the structures (most requested first, see
/// [`StreamingRenderer::probe_next_camera`]) and the pixels it left open.
pub(super) struct ProbeFound {
    pub demand: Demand,
    /// Pixels (packed `x | y << 16`) some ray of which needed one of `demand`'s structures.
    pub open_pixels: Vec<u32>,
}

impl<'a> StreamingRenderer<'a> {
    /// Traces the probe of `next` (same image size as the frame just rendered, whose buffers
    /// `fb` are): every `probe_stride`-th pixel, or only the pixels `again` (a later round:
    /// those an earlier round left open, packed `x | y << 16`); `verify`: a verifying round,
    /// every `probe_stride`-th pixel again, adding to the earlier rounds as `again` does.
    /// Returns what it met that is not
    /// resident: the structures some ray would open first (most requested first), then the
    /// rest of what its rays met; and the pixels some ray of which needed one of them. Resident
    /// structures it met count as seen by this frame, so the prefetch does not evict them.
    pub(super) fn probe_next_camera(
        &mut self,
        fb: &FrameBuffers,
        next: &CameraParams,
        opts: &RenderOptions,
        again: Option<&[u32]>,
        verify: bool,
    ) -> Result<ProbeFound> {
        // A later round (open pixels, or a verifying round over every pixel) adds to the
        // first round's sightings, need and marks.
        let later = again.is_some() || verify;
        let params = frame_params(next, opts, self.view.root_tlas, self.shading.address());
        crate::render::write_params(&fb.params, &params, &opts.shading)?;
        let pixels = u64::from(next.width) * u64::from(next.height);
        // On the clock `StreamOptions::clocked_probe`'s (`flying.rs`).
        let stride = self.probe_settings().stride.max(1);
        let (full, list) = if let Some(again) = again {
            (0, relist(again))
        } else if stride == 1 {
            (pixels as u32, Vec::new())
        } else {
            // Every stride-th pixel of each axis, from the middle of its stride × stride cell.
            let o = stride / 2;
            let list: Vec<u32> = (o..next.height)
                .step_by(stride as usize)
                .flat_map(|y| {
                    (o..next.width)
                        .step_by(stride as usize)
                        .map(move |x| pack_biased(x as i32, y as i32))
                })
                .collect();
            (0, list)
        };
        let rays = u64::from(full) + list.len() as u64;
        // A later round marks as the first did.
        let pass_rows = if later {
            self.frame.stats().probe_pass_rows
        } else {
            self.opts.pass_marks.rows(super::PassMarks::auto_window(
                self.frame.number(),
                self.frame.pass_marks_held(),
            ))
        };
        self.frame.stats_mut().probe_pass_rows = pass_rows;
        let resident: Vec<bool> = self.res.blases().iter().map(Option::is_some).collect();
        let PassReadback {
            stamps,
            requests,
            incomplete,
            trace_ms,
        } = self.trace_pass(
            fb,
            pixels,
            full,
            &list,
            false,
            probe_flags(pass_rows, self.opts.probe_paths),
        )?;
        let stamp = self.frame.stamp();
        if pass_rows > 0 {
            // Passed by a final ray only: as recent as the frame's last pass (a later round:
            // as the first round's), below what the probe met, so not kept by the prefetch.
            let at = if later {
                self.frame.first_stamp().saturating_sub(1)
            } else {
                stamp - 1
            };
            for (b, &v) in stamps.iter().enumerate() {
                if passed_mark(v, stamp) && self.res.has_blas(b) && self.topo.buildable(b) {
                    self.res.saw(b, at);
                    self.res.seen_by(b, at);
                    self.frame.stats_mut().probe_pass_marks += 1;
                }
            }
        }
        self.count_probe_need(&stamps, stamp, !later);
        // What the rounds saw together (a later round adds to the first's).
        self.frame
            .note_probe_sighting(&stamps, &resident, stamp, !later);
        self.frame.stats_mut().probe_rays += rays;
        self.frame.stats_mut().probe_ms += trace_ms;
        self.frame.stats_mut().probe_rounds += 1;
        let mut demand = Demand::default();
        for Sighting { blas: b, level } in self.sightings(&stamps, &requests, false) {
            // Needed (a ray's nearest) first by request count; then everything else it met.
            // By count alone: the prefetch builds for the next frame's first pass, where every
            // pixel starts over (`REQUEST_CAMERA` orders a frame's own passes).
            let n = if level == LEVEL_NEEDED {
                (requests.get(b as usize).copied().unwrap_or(0) & !REQUEST_CAMERA).max(1)
            } else {
                0
            };
            demand.need(b, n);
        }
        demand.sort();
        Ok(ProbeFound {
            demand,
            open_pixels: incomplete,
        })
    }

    /// `FrameStreamStats::probe_need_blases` and `probe_need_bytes` after a probe round
    /// (`first`: the first of the frame) that traced under `stamp`: the resident streamed
    /// BLASes some round's rays met or marked passed, with their bytes then (structures, and
    /// each of their meshes once).
    fn count_probe_need(&mut self, stamps: &[u32], stamp: u32, first: bool) {
        let mut need = self.frame.take_probe_need(first);
        for (b, &v) in stamps.iter().enumerate() {
            let used = v >> 2 == stamp || passed_mark(v, stamp);
            let Some(a) = self.res.blas(b).filter(|_| used && self.topo.buildable(b)) else {
                continue;
            };
            need.blases.entry(b).or_insert(a.size_bytes);
            for m in self.blas_meshes(b) {
                if let Some(g) = self.res.mesh(m) {
                    need.meshes
                        .entry(m)
                        .or_insert(self.res.mesh_budget_bytes(g));
                }
            }
        }
        self.frame.stats_mut().probe_need_blases = need.blases.len() as u32;
        let mesh_bytes = need.meshes.values().sum::<u64>();
        self.frame.stats_mut().probe_need_bytes = need.blases.values().sum::<u64>() + mesh_bytes;
        self.frame.stats_mut().probe_need_mesh_bytes = mesh_bytes;
        self.frame.keep_probe_need(need);
    }
}

/// What the probe rounds of one frame used of the resident set (`count_probe_need`): bytes per
/// BLAS and per mesh when first met.
#[derive(Default)]
pub(super) struct ProbeNeed {
    blases: std::collections::BTreeMap<usize, u64>,
    meshes: std::collections::BTreeMap<usize, u64>,
}
