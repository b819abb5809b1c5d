//! Sizes from the real driver (`vkGetAccelerationStructureBuildSizesKHR` through motu-gpu),
//! cached by shape, and the fitting harness that produced the model presets.

use std::cell::RefCell;
use std::collections::HashMap;

use motu_gpu::{AsBuildFlags, BlasGeometry, Context, ContextOptions, Requirement};
use motu_render::PackageGeometry;
use serde::Serialize;

use crate::presets::{LAVAPIPE, NVIDIA_H200};
use crate::sizes::{
    compact, compaction_text, fit_linear, AsSizes, BlasShape, Linear, ModelPreset, ModelSizes,
    SizeSource, SizeSourceInfo,
};
use crate::ReportError;

/// Real driver sizes. Compacted sizes are measured by building and compacting the package's
/// structures on the device ([`GpuSizes::measure_compaction`], `--measure`); without that they
/// use the ratio of the preset closest to this device.
pub struct GpuSizes {
    ctx: Context,
    flags: AsBuildFlags,
    compaction: &'static ModelPreset,
    /// Compacted ÷ built BLAS bytes, measured on this device for this package.
    measured_compaction: Option<f64>,
    blas_cache: RefCell<HashMap<BlasShape, AsSizes>>,
    tlas_cache: RefCell<HashMap<u64, AsSizes>>,
}

impl std::fmt::Debug for GpuSizes {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuSizes").field("ctx", &self.ctx).finish()
    }
}

impl GpuSizes {
    /// Opens a ray-tracing device (`device_index`, else `MOTU_DEVICE`, else the best one).
    pub fn open(device_index: Option<usize>) -> Result<Self, ReportError> {
        let ctx = Context::new(&ContextOptions {
            device_index,
            require: Requirement::RayTracing,
            ..Default::default()
        })
        .map_err(motu_gpu::GpuError::from)?;
        Ok(Self::with_context(ctx))
    }

    pub fn with_context(ctx: Context) -> Self {
        let compaction = nearest_preset(ctx.device_name());
        Self {
            ctx,
            flags: AsBuildFlags::default(),
            compaction,
            measured_compaction: None,
            blas_cache: RefCell::default(),
            tlas_cache: RefCell::default(),
        }
    }

    pub fn context(&self) -> &Context {
        &self.ctx
    }

    /// Builds every BLAS and TLAS of `pkg` on the device with compaction (as `motu render`
    /// does) and from then on sizes compacted BLASes with the measured ratio. Returns it.
    pub fn measure_compaction(
        &mut self,
        pkg: &motu_pack::ScenePackage,
    ) -> Result<f64, ReportError> {
        let view = pkg.view()?;
        let opts = motu_gpu::BuildOptions {
            compact: true,
            ..Default::default()
        };
        let scene = motu_gpu::GpuScene::build(&self.ctx, &view, &PackageGeometry(pkg), &opts)?;
        let r = scene.report();
        let ratio = if r.blas_bytes > 0 {
            r.blas_compacted_bytes as f64 / r.blas_bytes as f64
        } else {
            1.0
        };
        tracing::info!(
            built = r.blas_bytes,
            compacted = r.blas_compacted_bytes,
            ratio,
            "measured BLAS compaction"
        );
        self.measured_compaction = Some(ratio);
        Ok(ratio)
    }
}

/// The preset fitted on this very device, if any (model-vs-driver checks only assert there).
pub fn preset_for_device(device_name: &str) -> Option<&'static ModelPreset> {
    let n = device_name.to_ascii_lowercase();
    if n.contains("llvmpipe") {
        Some(&LAVAPIPE)
    } else if n.contains("h200") {
        Some(&NVIDIA_H200)
    } else {
        None
    }
}

/// The preset whose device is most like `device_name` (for the compaction ratio and fallbacks).
pub fn nearest_preset(device_name: &str) -> &'static ModelPreset {
    let n = device_name.to_ascii_lowercase();
    if n.contains("llvmpipe") || n.contains("lavapipe") {
        &LAVAPIPE
    } else {
        &NVIDIA_H200
    }
}

fn to_gpu(shape: &BlasShape) -> Vec<BlasGeometry> {
    match shape {
        BlasShape::Triangles(g) => g
            .iter()
            .map(|g| BlasGeometry::Triangles {
                vertex_count: g.vertex_count,
                triangle_count: g.triangle_count,
                indexed: true,
                opaque: g.opaque,
            })
            .collect(),
        BlasShape::Aabbs { box_count } => vec![BlasGeometry::Aabbs {
            aabb_count: *box_count,
            opaque: false,
        }],
    }
}

fn from_gpu(s: motu_gpu::AsBuildSizes) -> AsSizes {
    AsSizes {
        size_bytes: s.acceleration_structure_size_bytes,
        build_scratch_bytes: s.build_scratch_size_bytes,
    }
}

impl SizeSource for GpuSizes {
    fn info(&self) -> SizeSourceInfo {
        let mut notes = Vec::new();
        if let Some(r) = self.measured_compaction {
            notes.push(format!(
                "compacted BLAS = {r:.3} × built size (measured: this package built and compacted on this device)"
            ));
        } else if !self.compaction.compaction_measured {
            notes.push(format!(
                "compacted BLAS = {:.2} × built size (assumed; `--measure` builds and compacts \
                 the package on the device to measure it)",
                self.compaction.compaction_ratio
            ));
        }
        SizeSourceInfo {
            kind: "driver".into(),
            device: format!("#{} {}", self.ctx.device_index(), self.ctx.device_name()),
            preset: None,
            compaction: match self.measured_compaction {
                Some(r) => format!("ratio {r:.3} of the built size (measured on this device)"),
                None => compaction_text(self.compaction),
            },
            notes,
        }
    }

    fn blas_sizes(&self, shape: &BlasShape) -> Result<AsSizes, ReportError> {
        if let Some(s) = self.blas_cache.borrow().get(shape) {
            return Ok(*s);
        }
        let s = from_gpu(
            self.ctx
                .blas_build_sizes(&to_gpu(shape), self.flags)
                .map_err(motu_gpu::GpuError::from)?,
        );
        self.blas_cache.borrow_mut().insert(shape.clone(), s);
        Ok(s)
    }

    fn tlas_sizes(&self, instance_count: u64) -> Result<AsSizes, ReportError> {
        if let Some(s) = self.tlas_cache.borrow().get(&instance_count) {
            return Ok(*s);
        }
        let n = u32::try_from(instance_count).map_err(|_| {
            ReportError::Invalid(format!(
                "a TLAS of {instance_count} instances is over any device's limit"
            ))
        })?;
        let s = from_gpu(
            self.ctx
                .tlas_build_sizes(n, self.flags)
                .map_err(motu_gpu::GpuError::from)?,
        );
        self.tlas_cache.borrow_mut().insert(instance_count, s);
        Ok(s)
    }

    fn compacted_blas_bytes(&self, _shape: &BlasShape, built: AsSizes) -> u64 {
        match self.measured_compaction {
            Some(r) => (built.size_bytes as f64 * r).round() as u64,
            None => compact(self.compaction, built),
        }
    }

    fn max_instance_count(&self) -> u64 {
        self.ctx.limits().max_instance_count
    }

    fn tlas_updatable_sizes(&self, instance_count: u32) -> Result<Option<(u64, u64)>, ReportError> {
        use motu_gpu::FloorSizes;
        Ok(self.ctx.tlas_updatable(instance_count)?)
    }

    fn max_primitive_count(&self) -> u64 {
        self.ctx.limits().max_primitive_count
    }
}

/// Environment variable choosing the model preset when no device is used (`lavapipe`,
/// `nvidia-h200`; default `nvidia-h200`: render nodes are NVIDIA cards).
pub const ENV_REPORT_MODEL: &str = "MOTU_REPORT_MODEL";

/// The size source `motu report` uses: the driver of `device_index` (or of `MOTU_DEVICE`, or the
/// best ray-tracing device); without one, the model preset `MOTU_REPORT_MODEL` with a note
/// saying why. An explicitly requested device that cannot be opened is an error.
pub fn size_source_for_cli(
    device_index: Option<usize>,
) -> Result<Box<dyn SizeSource>, ReportError> {
    match GpuSizes::open(device_index) {
        Ok(g) => Ok(Box::new(g)),
        Err(e) if device_index.is_some() => Err(e),
        Err(e) => {
            let wanted = std::env::var(ENV_REPORT_MODEL).unwrap_or_default();
            let preset = if wanted.trim().is_empty() {
                &NVIDIA_H200
            } else {
                crate::presets::preset(wanted.trim()).ok_or_else(|| {
                    ReportError::Invalid(format!(
                        "{ENV_REPORT_MODEL}={wanted}: unknown preset (known: {})",
                        crate::presets::PRESETS.map(|p| p.name.as_str()).join(", ")
                    ))
                })?
            };
            tracing::info!(error = %e, preset = preset.name, "no ray-tracing device; using the size model");
            let mut m = ModelSizes::new(preset);
            m.notes
                .push(format!("no ray-tracing device ({e}); sizes are modelled"));
            Ok(Box::new(m))
        }
    }
}

/// One fitted size curve and the points behind it.
#[derive(Clone, Debug, Serialize)]
pub struct FittedCurve {
    pub what: String,
    pub line: Linear,
    pub max_relative_error: f64,
    pub points: Vec<(u64, u64)>,
}

/// A device's fitted model, as `fit_device` measures it.
#[derive(Clone, Debug, Serialize)]
pub struct DeviceFit {
    pub device: String,
    pub driver: String,
    pub max_instance_count: u64,
    pub max_primitive_count: u64,
    pub curves: Vec<FittedCurve>,
    /// Extra bytes per additional geometry in a triangle BLAS (64 geometries of equal share).
    pub blas_bytes_per_extra_geometry: f64,
    /// `(triangles, one geometry, split over two geometries)` BLAS sizes.
    pub two_geometry_points: Vec<(u64, u64, u64)>,
    /// `(triangles, vertices, size, scratch)`: BLAS sizes over vertex counts.
    pub vertex_points: Vec<(u64, u64, u64, u64)>,
    /// `(triangles, geometries, opaque geometries, size, scratch)`: triangles split evenly.
    pub geometry_points: Vec<(u64, u64, u64, u64, u64)>,
}

impl DeviceFit {
    /// The largest relative error over every curve.
    pub fn max_relative_error(&self) -> f64 {
        self.curves
            .iter()
            .map(|c| c.max_relative_error)
            .fold(0.0, f64::max)
    }

    /// This fit as a [`ModelPreset`] named `name` (its data file is `preset.to_json()`, what
    /// `presets/NAME.json` holds). Compaction is not fitted: `compaction_ratio` is carried over.
    pub fn to_preset(&self, name: &str, compaction_ratio: f64) -> Result<ModelPreset, ReportError> {
        let curve = |what: &str| {
            self.curves
                .iter()
                .find(|c| c.what == what)
                .map(|c| c.line.clone())
                .ok_or_else(|| ReportError::Invalid(format!("the fit has no {what} curve")))
        };
        Ok(ModelPreset {
            name: name.to_string(),
            device: self.device.clone(),
            driver: self.driver.clone(),
            blas_triangles: curve("blas_triangles")?,
            blas_triangles_scratch: curve("blas_triangles_scratch")?,
            blas_triangles_nonopaque: curve("blas_triangles_nonopaque")?,
            blas_triangles_nonopaque_scratch: curve("blas_triangles_nonopaque_scratch")?,
            blas_triangles_multi_scratch: curve("blas_triangles_multi_scratch")?,
            blas_bytes_per_extra_geometry: self.blas_bytes_per_extra_geometry,
            blas_aabbs: curve("blas_aabbs")?,
            blas_aabbs_scratch: curve("blas_aabbs_scratch")?,
            tlas: curve("tlas")?,
            tlas_scratch: curve("tlas_scratch")?,
            compaction_ratio,
            compaction_measured: false,
            max_instance_count: self.max_instance_count,
            max_primitive_count: self.max_primitive_count,
            fitted_max_relative_error: self.max_relative_error(),
            measured: self
                .curves
                .iter()
                .map(|c| (c.what.to_string(), c.points.clone()))
                .collect(),
        })
    }
}

/// The item counts the presets are fitted over (0 to 2^20): dense up to 256 (the small
/// table), sparse above (the line).
pub const FIT_COUNTS: [u64; 24] = [
    0, 1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128, 192, 256, 512, 1024, 4096, 16_384,
    65_536, 262_144, 1_048_576,
];

/// Queries sizes over [`FIT_COUNTS`] and fits every curve of a [`ModelPreset`]. Cheap: size
/// queries only, nothing is built.
pub fn fit_device(ctx: &Context) -> Result<DeviceFit, ReportError> {
    let src = GpuSizes::with_context(ctx.clone());
    let tri = |n: u64| {
        BlasShape::Triangles(vec![crate::sizes::TriangleGeometry {
            vertex_count: (n as u32).saturating_mul(3).max(3),
            triangle_count: n as u32,
            opaque: true,
        }])
    };
    let mut samples: Vec<(&str, Vec<(u64, AsSizes)>)> = Vec::new();
    let mut pts =
        |what, f: &dyn Fn(u64) -> Result<AsSizes, ReportError>| -> Result<(), ReportError> {
            let v = FIT_COUNTS
                .iter()
                .map(|&n| Ok((n, f(n)?)))
                .collect::<Result<Vec<_>, ReportError>>()?;
            samples.push((what, v));
            Ok(())
        };
    pts("blas_triangles", &|n| src.blas_sizes(&tri(n)))?;
    pts("blas_triangles_nonopaque", &|n| {
        src.blas_sizes(&BlasShape::Triangles(vec![
            crate::sizes::TriangleGeometry {
                vertex_count: (n as u32).saturating_mul(3).max(3),
                triangle_count: n as u32,
                opaque: false,
            },
        ]))
    })?;
    // NVIDIA builds multi-geometry BLASes with ~8× the scratch of one geometry.
    pts("blas_triangles_multi", &|n| {
        let half = |k: u64| crate::sizes::TriangleGeometry {
            vertex_count: (k as u32).saturating_mul(3).max(3),
            triangle_count: k as u32,
            opaque: true,
        };
        src.blas_sizes(&BlasShape::Triangles(vec![half(n / 2), half(n - n / 2)]))
    })?;
    pts("blas_aabbs", &|n| {
        src.blas_sizes(&BlasShape::Aabbs {
            box_count: n as u32,
        })
    })?;
    pts("tlas", &|n| src.tlas_sizes(n))?;
    let mut curves = Vec::new();
    for (what, v) in samples {
        for (suffix, pick) in [("", 0usize), ("_scratch", 1)] {
            if what == "blas_triangles_multi" && pick == 0 {
                continue; // sizes equal one geometry's (checked by `geometry_points`)
            }
            let points: Vec<(u64, u64)> = v
                .iter()
                .map(|(n, s)| {
                    (
                        *n,
                        if pick == 0 {
                            s.size_bytes
                        } else {
                            s.build_scratch_bytes
                        },
                    )
                })
                .collect();
            let (line, err) = fit_linear(&points);
            curves.push(FittedCurve {
                what: format!("{what}{suffix}"),
                line,
                max_relative_error: err,
                points,
            });
        }
    }
    let total = 65_536u32;
    let one = src.blas_sizes(&tri(u64::from(total)))?.size_bytes as f64;
    let split: Vec<_> = (0..64)
        .map(|_| crate::sizes::TriangleGeometry {
            vertex_count: total / 64 * 3,
            triangle_count: total / 64,
            opaque: true,
        })
        .collect();
    let many = src.blas_sizes(&BlasShape::Triangles(split))?.size_bytes as f64;
    let mut two_geometry_points = Vec::new();
    for n in [2u32, 8, 17, 49, 100, 1000, 10_000] {
        let half = |k: u32| crate::sizes::TriangleGeometry {
            vertex_count: k * 3,
            triangle_count: k,
            opaque: true,
        };
        let one = src.blas_sizes(&tri(u64::from(n)))?.size_bytes;
        let two = src
            .blas_sizes(&BlasShape::Triangles(vec![half(n / 2), half(n - n / 2)]))?
            .size_bytes;
        two_geometry_points.push((u64::from(n), one, two));
    }
    let mut vertex_points = Vec::new();
    for t in [4u32, 16, 64, 256, 1024, 16_384, 262_144] {
        for v in [3, t / 2 + 2, t, 2 * t, 3 * t] {
            let shape = BlasShape::Triangles(vec![crate::sizes::TriangleGeometry {
                vertex_count: v.max(3),
                triangle_count: t,
                opaque: true,
            }]);
            let s = src.blas_sizes(&shape)?;
            vertex_points.push((
                u64::from(t),
                u64::from(v.max(3)),
                s.size_bytes,
                s.build_scratch_bytes,
            ));
        }
    }
    let mut geometry_points = Vec::new();
    for t in [2u32, 48, 1000, 65_536] {
        for (g, opaque) in [
            (1u32, 1u32),
            (1, 0),
            (2, 2),
            (2, 1),
            (2, 0),
            (8, 8),
            (8, 4),
            (64, 64),
        ] {
            if g > t {
                continue;
            }
            let geoms: Vec<_> = (0..g)
                .map(|i| crate::sizes::TriangleGeometry {
                    vertex_count: 3 * (t / g),
                    triangle_count: t / g + u32::from(i < t % g),
                    opaque: i < opaque,
                })
                .collect();
            let s = src.blas_sizes(&BlasShape::Triangles(geoms))?;
            geometry_points.push((
                u64::from(t),
                u64::from(g),
                u64::from(opaque),
                s.size_bytes,
                s.build_scratch_bytes,
            ));
        }
    }
    Ok(DeviceFit {
        geometry_points,
        driver: ctx.report().driver,
        vertex_points,
        two_geometry_points,
        device: ctx.device_name().to_string(),
        max_instance_count: ctx.limits().max_instance_count,
        max_primitive_count: ctx.limits().max_primitive_count,
        curves,
        blas_bytes_per_extra_geometry: (many - one) / 63.0,
    })
}
