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
mod tests {
    use super::*;

    fn image() -> Aov {
        let mut a = Aov::new(8, 6);
        for (i, r) in a.records.iter_mut().enumerate() {
            if i % 5 != 0 {
                *r = AovRecord {
                    mesh: (i % 3) as u32,
                    primitive: i as u32,
                    t: 10.0 + i as f32,
                    lod: 0,
                    _pad: 0,
                    traces: 1,
                };
            }
        }
        a
    }

    #[test]
    fn detects_one_changed_pixel() {
        let a = image();
        let same = compare(&a, &a, DEFAULT_REL_EPS).unwrap();
        assert_eq!((same.mismatched, same.bbox), (0, None));
        let mut b = a.clone();
        b.records[3 * 8 + 5].primitive += 1;
        let r = compare(&a, &b, DEFAULT_REL_EPS).unwrap();
        assert_eq!(r.mismatched, 1);
        assert_eq!(r.total, 48);
        assert_eq!(r.bbox, Some([5, 3, 5, 3]));
        assert_eq!(&r.diff_rgba8[(3 * 8 + 5) * 4..][..4], &[255, 0, 0, 255]);
        assert!((r.fraction - 1.0 / 48.0).abs() < 1e-12);
    }

    #[test]
    fn distance_tolerance_miss_and_size() {
        let a = image();
        let mut b = a.clone();
        b.records[1].t *= 1.0 + 0.5 * DEFAULT_REL_EPS;
        assert_eq!(compare(&a, &b, DEFAULT_REL_EPS).unwrap().mismatched, 0);
        b.records[1].t = a.records[1].t * (1.0 + 3.0 * DEFAULT_REL_EPS);
        b.records[2] = AovRecord::MISS;
        let r = compare(&a, &b, DEFAULT_REL_EPS).unwrap();
        assert_eq!(r.mismatched, 2);
        assert_eq!(r.bbox, Some([1, 0, 2, 0]));
        // LOD and trace counts do not matter.
        let mut c = a.clone();
        c.records[1].lod = 3;
        c.records[1].traces = 9;
        assert_eq!(compare(&a, &c, DEFAULT_REL_EPS).unwrap().mismatched, 0);
        assert!(matches!(
            compare(&a, &Aov::new(6, 8), DEFAULT_REL_EPS),
            Err(CompareError::Size { .. })
        ));
    }
}
