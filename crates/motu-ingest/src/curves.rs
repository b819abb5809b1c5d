//! `curve` shapes as flat ribbons (`--curves ribbons`): motu traces triangles only, so a curve
//! becomes a strip of quads along its centreline, `width0`→`width1` wide. pbrt's "flat" curves
//! always face the ray; a fixed ribbon cannot, so it is oriented by the curve's normals when
//! given (`ribbon` curves) and otherwise perpendicular to the tangent and the most
//! perpendicular world axis — right for grass seen from the side, thin when seen along it.

use glam::Vec3;
use motu_scene::MeshData;
use pbrt_import::Curve;

/// Quads per Bézier segment (or per B-spline span).
pub const RIBBON_STEPS: usize = 4;

/// Points on the curve's centreline, `steps` per segment, with the matching parameter in
/// [0, 1] over the whole curve (for the width).
fn centreline(c: &Curve, steps: usize) -> Vec<(Vec3, f32)> {
    let p: Vec<Vec3> = c
        .control_points
        .iter()
        .map(|v| Vec3::from_array(*v))
        .collect();
    let cubic = c.degree >= 3;
    let mut out = Vec::new();
    let spans: Vec<[Vec3; 4]> = if c.basis == "bspline" {
        // Uniform B-spline → Bézier per span (degree 3; degree 2 is raised approximately).
        p.windows(4)
            .map(|w| {
                [
                    (w[0] + 4.0 * w[1] + w[2]) / 6.0,
                    (4.0 * w[1] + 2.0 * w[2]) / 6.0,
                    (2.0 * w[1] + 4.0 * w[2]) / 6.0,
                    (w[1] + 4.0 * w[2] + w[3]) / 6.0,
                ]
            })
            .collect()
    } else if cubic {
        p.windows(4)
            .step_by(3)
            .map(|w| [w[0], w[1], w[2], w[3]])
            .collect()
    } else {
        // Quadratic Bézier segments, raised to cubic.
        p.windows(3)
            .step_by(2)
            .map(|w| {
                [
                    w[0],
                    w[0] + (w[1] - w[0]) * (2.0 / 3.0),
                    w[2] + (w[1] - w[2]) * (2.0 / 3.0),
                    w[2],
                ]
            })
            .collect()
    };
    let n = spans.len().max(1);
    for (si, s) in spans.iter().enumerate() {
        for k in 0..=steps {
            if si > 0 && k == 0 {
                continue; // shared with the previous span's end
            }
            let t = k as f32 / steps as f32;
            let u = 1.0 - t;
            let pt = s[0] * (u * u * u)
                + s[1] * (3.0 * u * u * t)
                + s[2] * (3.0 * u * t * t)
                + s[3] * (t * t * t);
            out.push((pt, (si as f32 + t) / n as f32));
        }
    }
    out
}

/// The ribbon mesh of one curve, in the curve's space; `None` for a degenerate curve.
pub fn ribbon(c: &Curve) -> Option<MeshData> {
    let line = centreline(c, RIBBON_STEPS);
    if line.len() < 2 {
        return None;
    }
    let given_normal = c
        .normals
        .as_ref()
        .and_then(|n| n.first())
        .map(|n| Vec3::from_array(*n));
    let mut positions = Vec::with_capacity(line.len() * 2);
    for (i, &(pt, s)) in line.iter().enumerate() {
        let (a, b) = (
            line[i.saturating_sub(1)].0,
            line[(i + 1).min(line.len() - 1)].0,
        );
        let tangent = (b - a).normalize_or_zero();
        if tangent == Vec3::ZERO {
            return None;
        }
        let side = match given_normal {
            Some(n) => tangent.cross(n).normalize_or_zero(),
            None => {
                // The world axis least aligned with the tangent.
                let axis = [Vec3::X, Vec3::Y, Vec3::Z]
                    .into_iter()
                    .min_by(|p, q| p.dot(tangent).abs().total_cmp(&q.dot(tangent).abs()))
                    .unwrap_or(Vec3::X);
                tangent.cross(axis).normalize_or_zero()
            }
        };
        let half = 0.5 * (c.width0 + (c.width1 - c.width0) * s);
        positions.push((pt - side * half).to_array());
        positions.push((pt + side * half).to_array());
    }
    let mut indices = Vec::with_capacity((line.len() - 1) * 6);
    for i in 0..line.len() as u32 - 1 {
        let (a, b, c2, d) = (2 * i, 2 * i + 1, 2 * i + 2, 2 * i + 3);
        indices.extend_from_slice(&[a, b, d, a, d, c2]);
    }
    let m = MeshData {
        positions,
        normals: None,
        uvs: None,
        indices,
    };
    m.validate().ok().map(|_| m)
}

#[cfg(test)]
mod tests;
