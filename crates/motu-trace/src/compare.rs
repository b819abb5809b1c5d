//! Pixel-by-pixel comparison of two AOVs (`motu compare`).

use motu_abi::aov::{Aov, AovRecord, MISS};

/// Default relative distance tolerance: f32 transforms through several instance levels and
/// the GPU's own intersection arithmetic differ by ~1e-6 relative; 1e-3 leaves ample margin
/// while still catching a hit on the wrong surface.
pub const DEFAULT_REL_EPS: f32 = 1e-3;

#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum CompareError {
    #[error("AOV sizes differ: {a_width}×{a_height} vs {b_width}×{b_height}")]
    Size {
        a_width: u32,
        a_height: u32,
        b_width: u32,
        b_height: u32,
    },
}

#[derive(Clone, Debug, PartialEq)]
pub struct CompareReport {
    pub mismatched: u64,
    pub total: u64,
    /// `mismatched / total` (0 for an empty image).
    pub fraction: f64,
    /// Inclusive `[x0, y0, x1, y1]` of the mismatches.
    pub bbox: Option<[u32; 4]>,
    /// Red where pixels mismatch, grey where both hit, black where both miss.
    pub diff_rgba8: Vec<u8>,
}

/// `true` when the two records agree: both miss, or same mesh and primitive with distances
/// within `rel_eps` of the larger. LOD and trace counts are not compared.
pub fn records_match(a: &AovRecord, b: &AovRecord, rel_eps: f32) -> bool {
    if a.mesh == MISS || b.mesh == MISS {
        return a.mesh == b.mesh;
    }
    if a.mesh != b.mesh || a.primitive != b.primitive {
        return false;
    }
    let scale = a.t.abs().max(b.t.abs());
    (a.t - b.t).abs() <= rel_eps * scale
}

/// Compares `a` and `b`; an error when their sizes differ.
pub fn compare(a: &Aov, b: &Aov, rel_eps: f32) -> Result<CompareReport, CompareError> {
    if (a.width, a.height) != (b.width, b.height) || a.records.len() != b.records.len() {
        return Err(CompareError::Size {
            a_width: a.width,
            a_height: a.height,
            b_width: b.width,
            b_height: b.height,
        });
    }
    let w = a.width.max(1);
    let mut mismatched = 0u64;
    let mut bbox: Option<[u32; 4]> = None;
    let mut diff = Vec::with_capacity(a.records.len() * 4);
    for (i, (ra, rb)) in a.records.iter().zip(&b.records).enumerate() {
        let (x, y) = (i as u32 % w, i as u32 / w);
        if records_match(ra, rb, rel_eps) {
            let v = if ra.mesh == MISS { 0 } else { 96 };
            diff.extend_from_slice(&[v, v, v, 255]);
        } else {
            mismatched += 1;
            diff.extend_from_slice(&[255, 0, 0, 255]);
            bbox = Some(match bbox {
                None => [x, y, x, y],
                Some([x0, y0, x1, y1]) => [x0.min(x), y0.min(y), x1.max(x), y1.max(y)],
            });
        }
    }
    let total = a.records.len() as u64;
    Ok(CompareReport {
        mismatched,
        total,
        fraction: if total == 0 {
            0.0
        } else {
            mismatched as f64 / total as f64
        },
        bbox,
        diff_rgba8: diff,
    })
}

#[cfg(test)]
mod tests;
