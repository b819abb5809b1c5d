//! One `motu render`: the chosen backend's render path (CPU, full GPU build, recorded camera
//! path, or streaming), then the `--stats` object every path shares
//! ([`crate::stats::RenderStats`], CLI.md's keys) and the truncation check.

use crate::gpu::PathStats;
use crate::settings::{RenderEvent, RenderSettings};
use crate::stats::{LodStats, RenderStats};
use crate::{Backend, LodChoice, RenderError};
use motu_abi::aov::Aov;
use motu_abi::camera::CameraParams;
use motu_abi::HierarchyView;
use motu_pack::ScenePackage;
use std::path::Path;

/// What to render: the package (and its path and `--subset`, for the stats), the view of it,
/// the camera, an optional recorded path, and the LOD mode chosen for it.
pub struct RenderJob<'a> {
    pub package: &'a ScenePackage,
    pub package_path: &'a Path,
    pub subset: &'a [String],
    pub view: &'a HierarchyView<'a>,
    /// The camera rendered (the recorded path's last one where there is a path).
    pub camera: CameraParams,
    /// `--camera-path`: one frame per camera.
    pub recorded: Option<&'a [CameraParams]>,
    pub lod: &'a LodChoice,
    /// When the command began (`--stats` times the first streamed pixel from it); `None`:
    /// from the render's start.
    pub started: Option<std::time::Instant>,
}

/// A rendered image: the last frame's AOV and pixels, and the `--stats` object.
#[derive(Debug)]
pub struct Rendered {
    pub aov: Aov,
    pub rgba8: Vec<u8>,
    /// CLI.md's `--stats` keys (the backend's stats, the render path's, the session's).
    pub stats: RenderStats,
    /// A streamed render's structure cache, its directory writes possibly still queued: the
    /// caller drops it after writing its outputs, so the image does not wait for the disk
    /// (dropping waits for the writes).
    pub pending_cache_writes: Option<PendingCacheWrites>,
}

/// See [`Rendered::pending_cache_writes`].
pub struct PendingCacheWrites {
    /// Held for its drop, which waits for the queued writes.
    _cache: motu_gpu::StructureCache,
}

impl std::fmt::Debug for PendingCacheWrites {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_tuple("PendingCacheWrites").finish()
    }
}

impl Rendered {
    /// Median milliseconds per frame.
    pub fn ms_per_frame(&self) -> f64 {
        self.stats.ms_per_frame()
    }

    pub fn rays_per_second(&self) -> f64 {
        self.stats.rays_per_second()
    }

    pub fn traces_per_ray(&self) -> f64 {
        self.stats.traces_per_ray()
    }
}

/// Renders `job` with `settings`, reporting streamed frames and allowed truncation to
/// `progress`. A truncated traversal (or an unfinished streamed frame) is an error unless the
/// settings allow it.
pub fn render(
    job: &RenderJob<'_>,
    settings: &RenderSettings,
    progress: &mut dyn FnMut(RenderEvent<'_>),
) -> Result<Rendered, RenderError> {
    let s = settings;
    let (pkg, view, camera, recorded) = (job.package, job.view, job.camera, job.recorded);
    let lod = s.lod;
    let instance_lod = job.lod.instance.as_ref();
    // The image's camera: the streamed sweep's last one, else the job's.
    let mut image_camera = camera;
    let mut pending_cache_writes = None;
    let (aov, rgba8, path): (Aov, Vec<u8>, PathStats) = match (s.backend, &s.stream) {
        (Backend::Cpu, _) => {
            let cams = recorded
                .map(<[CameraParams]>::to_vec)
                .unwrap_or_else(|| vec![camera; s.frames as usize]);
            crate::cpu::render_cpu(s, pkg, view, lod, instance_lod, &cams)?
        }
        (backend, Some(stream)) => {
            let done = crate::stream::render_streaming(s, stream, job, backend, progress)?;
            image_camera = done.camera;
            pending_cache_writes = done.cache.map(|c| PendingCacheWrites { _cache: c });
            done.rendered
        }
        (backend, None) => match recorded {
            Some(cams) => {
                crate::gpu::render_gpu_path(s, pkg, view, cams, backend, instance_lod, None)?
            }
            None => crate::gpu::render_gpu(s, pkg, view, &camera, backend, instance_lod, None)?,
        },
    };
    let mut rgba8 = rgba8;
    let denoised = match (s.denoise, s.view) {
        (true, motu_gpu::View::Shaded) => {
            let albedo = texture_albedo(job, settings, &image_camera)?;
            Some(denoise(
                job,
                &image_camera,
                &aov,
                &mut rgba8,
                albedo.as_ref(),
            ))
        }
        _ => None,
    };
    let PathStats {
        frame,
        truncated_rays,
        full_build,
        path_ms_per_frame,
        fallback_pixels,
        stream,
        stream_fit,
        pipeline_executables,
    } = path;
    // A `--stream` render whose budget held the scene built it as the full build does.
    let blas_build = match &stream_fit {
        Some(f) if f.full_build => crate::stream::full_build_settings(s).blas_build(),
        _ => s.blas_build(),
    };
    let stats = RenderStats {
        frame,
        truncated_rays,
        full_build,
        path_ms_per_frame,
        fallback_pixels,
        stream,
        stream_fit,
        denoise: denoised.as_ref().map(Into::into),
        lod: lod_stats(job.lod),
        blas_build: blas_build.name(),
        subset: job.subset.to_vec(),
        package: job.package_path.display().to_string(),
        pipeline_executables,
    };
    // A truncated traversal is a wrong image: an error unless explicitly allowed.
    let truncated = stats.truncated_rays.unwrap_or(0);
    let overflows = stats.frame.stack_overflows;
    if truncated > 0 || overflows > 0 {
        let what = format!(
            "{truncated} ray(s) were cut short ({overflows} traversal stack overflows with --stack-size {}; --max-traces-per-ray {}): their hits may be wrong (exponentially deep instancing?)",
            s.limits.stack_size, s.limits.max_traces_per_ray
        );
        if !s.limits.allow_truncated {
            return Err(RenderError::Truncated { what });
        }
        progress(RenderEvent::TruncatedWritten { what: &what });
    }
    Ok(Rendered {
        aov,
        rgba8,
        stats,
        pending_cache_writes,
    })
}

/// `--denoise` on a scene with textured materials: the same camera's `albedo` view (the
/// textured base colour at each primary hit) on the same backend and path (full build or
/// streamed), for the guide. A second render of primary rays only; `None` without textures.
fn texture_albedo(
    job: &RenderJob<'_>,
    settings: &RenderSettings,
    camera: &CameraParams,
) -> Result<Option<(Aov, Vec<u8>)>, RenderError> {
    if !crate::denoise::has_textured_materials(job.view) {
        return Ok(None);
    }
    let s = RenderSettings {
        view: motu_gpu::View::Albedo,
        frames: 1,
        denoise: false,
        ..settings.clone()
    };
    let cameras = [*camera];
    let albedo_job = RenderJob {
        camera: *camera,
        recorded: s.stream.is_some().then_some(&cameras[..]),
        ..*job
    };
    let (aov, rgba8, _) = match (s.backend, &s.stream) {
        (Backend::Cpu, _) => crate::cpu::render_cpu(
            &s,
            job.package,
            job.view,
            s.lod,
            job.lod.instance.as_ref(),
            &cameras,
        )?,
        (backend, Some(stream)) => {
            crate::stream::render_streaming(&s, stream, &albedo_job, backend, &mut |_| {})?.rendered
        }
        (backend, None) => crate::gpu::render_gpu(
            &s,
            job.package,
            job.view,
            camera,
            backend,
            job.lod.instance.as_ref(),
            None,
        )?,
    };
    Ok(Some((aov, rgba8)))
}

/// `--denoise`: filters the shaded image with the guide its AOV gives (the materials' base
/// colours by source mesh; where `albedo` has the frame's albedo view, the textured colour).
fn denoise(
    job: &RenderJob<'_>,
    camera: &CameraParams,
    aov: &Aov,
    rgba8: &mut [u8],
    albedo: Option<&(Aov, Vec<u8>)>,
) -> crate::denoise::DenoiseStats {
    let base = crate::denoise::mesh_base_colours(job.view);
    let mut guide = crate::denoise::guide_from_aov(aov, camera, |mesh| {
        base.get(&mesh).copied().unwrap_or([0.5; 3])
    });
    if let Some((albedo_aov, albedo_rgba8)) = albedo {
        crate::denoise::add_texture_albedo(&mut guide, aov, albedo_rgba8, albedo_aov);
    }
    crate::denoise::denoise_rgba8(
        rgba8,
        aov.width,
        aov.height,
        &guide,
        crate::denoise::pixel_footprint(camera),
        &crate::denoise::DenoiseOptions::default(),
    )
}

/// The LOD mode and its instance/selector counts.
fn lod_stats(lod: &LodChoice) -> LodStats {
    let instance_lod = lod.instance.as_ref();
    LodStats {
        lod_mode: lod.mode,
        lod_mode_reason: lod.reason,
        lod_instances: instance_lod.map_or(0, |il| il.slots.len()),
        lod_traversal_selectors: instance_lod.map_or(lod.selector_pis, |il| il.traversal_selectors),
    }
}

#[cfg(test)]
mod tests;
