//! Where acceleration-structure sizes come from: a [`SizeSource`] answers "how big is this
//! BLAS/TLAS and its build scratch". [`ModelSizes`] answers from a linear model fitted on a
//! real driver ([`ModelPreset`]); `GpuSizes` (in `gpu`) asks the driver itself.
//!
//! # The model
//! Every size is `base + per_item × items` with `items` = triangles (triangle BLAS), boxes
//! (AABB BLAS) or instances (TLAS); triangle BLASes add `per_geometry` for each geometry
//! beyond the first. Compaction is a constant ratio of the built BLAS size. The constants were
//! fitted by least squares on relative error over sizes from 1 to 2^20 items with motu's build
//! flags (fast trace + allow compaction); `fit_*` in this module's tests refits them
//! (`cargo test -p motu-report -- --ignored --nocapture fit_presets`).

use std::borrow::Cow;

use serde::{Deserialize, Serialize};

use crate::ReportError;

/// Bytes per `VkAccelerationStructureInstanceKHR` in a TLAS build input.
pub const INSTANCE_RECORD_SIZE_BYTES: u64 = 64;
/// Bytes per `VkAabbPositionsKHR` in an AABB BLAS build input.
pub const AABB_RECORD_SIZE_BYTES: u64 = 24;
/// Acceleration structures start at multiples of this in their buffer (Vulkan spec).
pub const AS_ALIGNMENT_BYTES: u64 = 256;

/// What one acceleration-structure build needs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct AsSizes {
    /// The structure as built (before compaction).
    pub size_bytes: u64,
    pub build_scratch_bytes: u64,
}

/// One triangle geometry of a BLAS, by counts (what a size query needs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
pub struct TriangleGeometry {
    pub vertex_count: u32,
    pub triangle_count: u32,
    /// Alpha-tested meshes are not opaque (changes flags, not sizes, on known drivers).
    pub opaque: bool,
}

/// A bottom-level structure by shape.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub enum BlasShape {
    Triangles(Vec<TriangleGeometry>),
    Aabbs { box_count: u32 },
}

impl BlasShape {
    pub fn primitive_count(&self) -> u64 {
        match self {
            BlasShape::Triangles(g) => g.iter().map(|g| u64::from(g.triangle_count)).sum(),
            BlasShape::Aabbs { box_count } => u64::from(*box_count),
        }
    }
}

/// Where sizes came from, for the report's header and JSON.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SizeSourceInfo {
    /// `driver` (vkGetAccelerationStructureBuildSizesKHR) or `model`.
    pub kind: String,
    /// The device the sizes are for (the queried one, or the one the model was fitted on).
    pub device: String,
    /// The model preset, for `model`.
    pub preset: Option<String>,
    /// Compacted sizes: how they were obtained.
    pub compaction: String,
    /// Caveats (a fallback, an unmeasured ratio).
    pub notes: Vec<String>,
}

/// Answers size questions for the report. Implementations may cache (sizes repeat a lot).
pub trait SizeSource {
    fn info(&self) -> SizeSourceInfo;
    fn blas_sizes(&self, shape: &BlasShape) -> Result<AsSizes, ReportError>;
    /// `instance_count` never exceeds [`SizeSource::max_instance_count`] (callers split).
    fn tlas_sizes(&self, instance_count: u64) -> Result<AsSizes, ReportError>;
    /// The compacted size of a BLAS built with `built`.
    fn compacted_blas_bytes(&self, shape: &BlasShape, built: AsSizes) -> u64;
    /// `maxInstanceCount` of the target device.
    fn max_instance_count(&self) -> u64;
    /// `maxPrimitiveCount` of the target device.
    fn max_primitive_count(&self) -> u64;
    /// (structure, update scratch) of a TLAS built to be updated (`--stream-tlas update`);
    /// `None` where the source cannot size one (models are fitted on plain builds).
    fn tlas_updatable_sizes(
        &self,
        _instance_count: u32,
    ) -> Result<Option<(u64, u64)>, ReportError> {
        Ok(None)
    }
}

/// A size curve in bytes over an item count: the sizes measured at small counts (up to
/// [`FIT_TAIL_FROM`] items, interpolated between; drivers have fixed-size headers and node
/// granularity there) and `base + per_item × items` above, where every driver seen is linear.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Linear {
    /// `(items, bytes)`, ascending items, at least one entry.
    pub small: Cow<'static, [(u64, u64)]>,
    #[serde(deserialize_with = "exact_f64::deserialize")]
    pub base_bytes: f64,
    #[serde(deserialize_with = "exact_f64::deserialize")]
    pub bytes_per_item: f64,
}

/// Floats in preset data files are decimal strings (`"104.00000000000001"`), parsed by Rust's
/// correctly rounded `str::parse`: serde_json's own float parsing may be one ulp off, and a
/// preset must equal the fit of its recorded points exactly. Plain numbers are accepted too.
mod exact_f64 {
    use serde::{Deserialize, Deserializer};

    #[derive(Deserialize)]
    #[serde(untagged)]
    enum Float {
        Text(String),
        Number(f64),
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        match Float::deserialize(d)? {
            Float::Number(v) => Ok(v),
            Float::Text(t) => t.parse().map_err(serde::de::Error::custom),
        }
    }

    /// How [`deserialize`] wants a float written: exact and shortest.
    pub fn text(v: f64) -> String {
        format!("\"{v:?}\"")
    }
}

impl Linear {
    pub const fn new(small: &'static [(u64, u64)], base_bytes: f64, bytes_per_item: f64) -> Self {
        Self {
            small: Cow::Borrowed(small),
            base_bytes,
            bytes_per_item,
        }
    }
    /// A line alone (tests, hand-made presets).
    pub fn line(base_bytes: f64, bytes_per_item: f64) -> Self {
        let at = |n: u64| (base_bytes + bytes_per_item * n as f64).max(0.0).round() as u64;
        Self {
            small: Cow::Owned(vec![(1, at(1))]),
            base_bytes,
            bytes_per_item,
        }
    }
    pub fn eval(&self, items: u64) -> u64 {
        let line = || {
            (self.base_bytes + self.bytes_per_item * items as f64)
                .max(0.0)
                .round() as u64
        };
        let (Some(&first), Some(&last)) = (self.small.first(), self.small.last()) else {
            return line();
        };
        if items > last.0 {
            return line();
        }
        if items <= first.0 {
            return first.1;
        }
        let mut prev = first;
        for &p in &self.small[1..] {
            if items <= p.0 {
                let t = (items - prev.0) as f64 / (p.0 - prev.0).max(1) as f64;
                return (prev.1 as f64 + t * (p.1 as f64 - prev.1 as f64)).round() as u64;
            }
            prev = p;
        }
        last.1
    }
}

/// A size model fitted on one device and driver. The built-in ones are data
/// (`presets/*.json`, see `presets.rs`); [`ModelPreset::to_json`] writes that file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelPreset {
    pub name: String,
    pub device: String,
    pub driver: String,
    /// Opaque triangles (motu's default).
    pub blas_triangles: Linear,
    pub blas_triangles_scratch: Linear,
    /// Non-opaque triangles (alpha-tested meshes; NVIDIA builds them ~25% smaller).
    pub blas_triangles_nonopaque: Linear,
    pub blas_triangles_nonopaque_scratch: Linear,
    /// Scratch of triangle BLASes with two or more geometries (NVIDIA: ~8× one geometry's).
    pub blas_triangles_multi_scratch: Linear,
    /// Added per geometry beyond the first.
    #[serde(deserialize_with = "exact_f64::deserialize")]
    pub blas_bytes_per_extra_geometry: f64,
    pub blas_aabbs: Linear,
    pub blas_aabbs_scratch: Linear,
    pub tlas: Linear,
    pub tlas_scratch: Linear,
    /// Compacted / built BLAS size.
    #[serde(deserialize_with = "exact_f64::deserialize")]
    pub compaction_ratio: f64,
    /// Whether `compaction_ratio` was measured (else an assumption, see its doc).
    pub compaction_measured: bool,
    pub max_instance_count: u64,
    pub max_primitive_count: u64,
    /// The largest relative error of the model against the sizes it was fitted on.
    #[serde(deserialize_with = "exact_f64::deserialize")]
    pub fitted_max_relative_error: f64,
    /// The measured `(items, bytes)` behind each curve, by curve name (re-checked by tests).
    #[serde(skip_serializing)]
    pub measured: Vec<(String, Vec<(u64, u64)>)>,
}

/// The curves of a [`ModelPreset`], by the names [`ModelPreset::curve`] takes.
pub const CURVE_NAMES: [&str; 9] = [
    "blas_triangles",
    "blas_triangles_scratch",
    "blas_triangles_nonopaque",
    "blas_triangles_nonopaque_scratch",
    "blas_triangles_multi_scratch",
    "blas_aabbs",
    "blas_aabbs_scratch",
    "tlas",
    "tlas_scratch",
];

impl ModelPreset {
    /// The preset as its data file: one field a line, in declaration order, floats written
    /// exactly (shortest round-trip), so `from_json(to_json(p)) == p`.
    pub fn to_json(&self) -> String {
        // Serializing these plain values cannot fail.
        fn j<T: Serialize + ?Sized>(v: &T) -> String {
            serde_json::to_string(v).unwrap_or_default()
        }
        let mut lines = vec![
            format!("\"name\": {}", j(&self.name)),
            format!("\"device\": {}", j(&self.device)),
            format!("\"driver\": {}", j(&self.driver)),
        ];
        for what in CURVE_NAMES {
            if let Some(c) = self.curve(what) {
                lines.push(format!(
                    "\"{what}\": {{\"small\": {}, \"base_bytes\": {}, \"bytes_per_item\": {}}}",
                    j(&c.small),
                    exact_f64::text(c.base_bytes),
                    exact_f64::text(c.bytes_per_item)
                ));
            }
        }
        lines.push(format!(
            "\"blas_bytes_per_extra_geometry\": {}",
            exact_f64::text(self.blas_bytes_per_extra_geometry)
        ));
        lines.push(format!(
            "\"compaction_ratio\": {}",
            exact_f64::text(self.compaction_ratio)
        ));
        lines.push(format!(
            "\"compaction_measured\": {}",
            j(&self.compaction_measured)
        ));
        lines.push(format!(
            "\"max_instance_count\": {}",
            j(&self.max_instance_count)
        ));
        lines.push(format!(
            "\"max_primitive_count\": {}",
            j(&self.max_primitive_count)
        ));
        lines.push(format!(
            "\"fitted_max_relative_error\": {}",
            exact_f64::text(self.fitted_max_relative_error)
        ));
        let measured: Vec<String> = self
            .measured
            .iter()
            .map(|(what, points)| format!("    [{}, {}]", j(what), j(points)))
            .collect();
        lines.push(format!("\"measured\": [\n{}\n  ]", measured.join(",\n")));
        format!("{{\n  {}\n}}\n", lines.join(",\n  "))
    }

    /// Reads a preset data file (what [`ModelPreset::to_json`] writes).
    pub fn from_json(text: &str) -> Result<Self, ReportError> {
        serde_json::from_str(text).map_err(ReportError::Preset)
    }

    /// The curve named as in [`crate::FittedCurve::what`].
    pub fn curve(&self, what: &str) -> Option<&Linear> {
        Some(match what {
            "blas_triangles" => &self.blas_triangles,
            "blas_triangles_scratch" => &self.blas_triangles_scratch,
            "blas_triangles_nonopaque" => &self.blas_triangles_nonopaque,
            "blas_triangles_nonopaque_scratch" => &self.blas_triangles_nonopaque_scratch,
            "blas_triangles_multi_scratch" => &self.blas_triangles_multi_scratch,
            "blas_aabbs" => &self.blas_aabbs,
            "blas_aabbs_scratch" => &self.blas_aabbs_scratch,
            "tlas" => &self.tlas,
            "tlas_scratch" => &self.tlas_scratch,
            _ => return None,
        })
    }
}

impl ModelPreset {
    pub fn blas_sizes(&self, shape: &BlasShape) -> AsSizes {
        match shape {
            BlasShape::Triangles(geoms) => {
                // Opaque and non-opaque triangles cost differently; a mixed BLAS is modelled
                // as the triangle-weighted mix of both curves at its total count.
                let tris = shape.primitive_count();
                let opaque: u64 = geoms
                    .iter()
                    .filter(|g| g.opaque)
                    .map(|g| u64::from(g.triangle_count))
                    .sum();
                let w = if tris == 0 {
                    1.0
                } else {
                    opaque as f64 / tris as f64
                };
                let mix = |a: &Linear, b: &Linear| {
                    (a.eval(tris) as f64 * w + b.eval(tris) as f64 * (1.0 - w)).round() as u64
                };
                let extra =
                    geoms.len().saturating_sub(1) as f64 * self.blas_bytes_per_extra_geometry;
                AsSizes {
                    size_bytes: mix(&self.blas_triangles, &self.blas_triangles_nonopaque)
                        + extra.round() as u64,
                    build_scratch_bytes: if geoms.len() > 1 {
                        self.blas_triangles_multi_scratch.eval(tris)
                    } else {
                        mix(
                            &self.blas_triangles_scratch,
                            &self.blas_triangles_nonopaque_scratch,
                        )
                    },
                }
            }
            BlasShape::Aabbs { box_count } => AsSizes {
                size_bytes: self.blas_aabbs.eval(u64::from(*box_count)),
                build_scratch_bytes: self.blas_aabbs_scratch.eval(u64::from(*box_count)),
            },
        }
    }

    pub fn tlas_sizes(&self, instance_count: u64) -> AsSizes {
        AsSizes {
            size_bytes: self.tlas.eval(instance_count),
            build_scratch_bytes: self.tlas_scratch.eval(instance_count),
        }
    }
}

/// Sizes from a fitted model: no device needed.
#[derive(Clone, Debug)]
pub struct ModelSizes {
    pub preset: &'static ModelPreset,
    /// Shown with the report's size notes (e.g. why no device was used).
    pub notes: Vec<String>,
}

impl ModelSizes {
    pub fn new(preset: &'static ModelPreset) -> Self {
        Self {
            preset,
            notes: Vec::new(),
        }
    }
}

impl SizeSource for ModelSizes {
    fn info(&self) -> SizeSourceInfo {
        let p = self.preset;
        let mut notes = self.notes.clone();
        notes.push(format!(
            "modelled sizes (fitted on {} / {}; largest error on the fitting sizes {:.1}%)",
            p.device,
            p.driver,
            p.fitted_max_relative_error * 100.0
        ));
        if !p.compaction_measured {
            notes.push(format!(
                "compacted BLAS = {:.2} × built size (an assumption, not measured)",
                p.compaction_ratio
            ));
        }
        SizeSourceInfo {
            kind: "model".into(),
            device: p.device.clone(),
            preset: Some(p.name.clone()),
            compaction: compaction_text(p),
            notes,
        }
    }
    fn blas_sizes(&self, shape: &BlasShape) -> Result<AsSizes, ReportError> {
        Ok(self.preset.blas_sizes(shape))
    }
    fn tlas_sizes(&self, instance_count: u64) -> Result<AsSizes, ReportError> {
        Ok(self.preset.tlas_sizes(instance_count))
    }
    fn compacted_blas_bytes(&self, _shape: &BlasShape, built: AsSizes) -> u64 {
        compact(self.preset, built)
    }
    fn max_instance_count(&self) -> u64 {
        self.preset.max_instance_count
    }
    fn max_primitive_count(&self) -> u64 {
        self.preset.max_primitive_count
    }
}

pub(crate) fn compaction_text(p: &ModelPreset) -> String {
    format!(
        "ratio {:.2} of the built size ({}, preset {})",
        p.compaction_ratio,
        if p.compaction_measured {
            "measured"
        } else {
            "assumed"
        },
        p.name
    )
}

pub(crate) fn compact(p: &ModelPreset, built: AsSizes) -> u64 {
    (built.size_bytes as f64 * p.compaction_ratio).round() as u64
}

/// Fits [`Linear`] to `(items, bytes)` (ascending items): the points up to
/// [`FIT_TAIL_FROM`] items become the small table, and a least-squares line minimising
/// relative error is fitted over the points from [`FIT_TAIL_FROM`] up. Returns the largest
/// relative error over all points. Used to refit presets.
pub fn fit_linear(points: &[(u64, u64)]) -> (Linear, f64) {
    let tail: Vec<(u64, u64)> = points
        .iter()
        .copied()
        .filter(|p| p.0 >= FIT_TAIL_FROM)
        .collect();
    let fit_on = if tail.len() >= 2 { &tail[..] } else { points };
    // Weighted least squares with weights 1/y² (relative error).
    let (mut sw, mut sx, mut sy, mut sxx, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for &(x, y) in fit_on {
        let (x, y) = (x as f64, y as f64);
        let w = 1.0 / y.max(1.0).powi(2);
        sw += w;
        sx += w * x;
        sy += w * y;
        sxx += w * x * x;
        sxy += w * x * y;
    }
    let det = sw * sxx - sx * sx;
    let (base, per) = if det.abs() < f64::EPSILON {
        (if sw > 0.0 { sy / sw } else { 0.0 }, 0.0)
    } else {
        ((sxx * sy - sx * sxy) / det, (sw * sxy - sx * sy) / det)
    };
    let small: Vec<(u64, u64)> = points
        .iter()
        .copied()
        .filter(|p| p.0 <= FIT_TAIL_FROM)
        .collect();
    let line = Linear {
        small: Cow::Owned(small),
        base_bytes: base,
        bytes_per_item: per,
    };
    let err = points
        .iter()
        .map(|&(x, y)| relative_error(line.eval(x), y))
        .fold(0.0, f64::max);
    (line, err)
}

/// Fits use points from this many items up (see [`fit_linear`]).
pub const FIT_TAIL_FROM: u64 = 256;

/// `|model − measured| / measured` (0 when both are 0).
pub fn relative_error(model: u64, measured: u64) -> f64 {
    if measured == 0 {
        return if model == 0 { 0.0 } else { 1.0 };
    }
    (model as f64 - measured as f64).abs() / measured as f64
}

#[cfg(test)]
mod tests;
