use super::*;

/// The shader's unpacking and dequantisation (`candidates.glsl`'s `proxy_entry`); the
/// levels alone (no pad) must hold the box already.
fn unpacked(bounds: &[f32; 6], w: [u32; 2]) -> Option<[f32; 6]> {
    let with_pad = unpacked_levels(bounds, w, true)?;
    let levels = unpacked_levels(bounds, w, false)?;
    assert!(holds(&with_pad, &levels));
    Some(levels)
}

fn unpacked_levels(bounds: &[f32; 6], w: [u32; 2], pad: bool) -> Option<[f32; 6]> {
    let q = [
        w[0] as u8,
        (w[0] >> 8) as u8,
        (w[0] >> 16) as u8,
        (w[0] >> 24) as u8,
        w[1] as u8,
        (w[1] >> 8) as u8,
    ];
    if q[0] > q[3] {
        return None; // ALWAYS
    }
    let r = reference(bounds);
    Some(std::array::from_fn(|i| {
        if pad {
            dequantised(&r, i % 3, q[i], i >= 3)
        } else {
            level(&r, i % 3, q[i])
        }
    }))
}

fn holds(outer: &[f32; 6], inner: &[f32; 6]) -> bool {
    (0..3).all(|a| outer[a] <= inner[a] && outer[3 + a] >= inner[3 + a])
}

/// A small deterministic generator (no test-only dependency).
struct Lcg(u64);
impl Lcg {
    fn f(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.f()
    }
}

#[test]
fn quantised_boxes_hold_the_exact_member_boxes() {
    let mut g = Lcg(7);
    let mut always = 0;
    let mut tight = 0;
    for case in 0..4000 {
        // Far from the origin (island-sized coordinates) and near it; rotated, scaled.
        let offset = if case % 2 == 0 {
            0.0
        } else {
            g.range(-5e4, 5e4)
        };
        let blas_lo = [g.range(-10.0, 0.0), g.range(-10.0, 0.0), g.range(-1.0, 0.0)];
        let blas_hi = [g.range(0.0, 10.0), g.range(0.0, 10.0), g.range(0.0, 20.0)];
        let n = 1 + case % 16;
        let placements: Vec<[f32; 12]> = (0..n)
            .map(|_| {
                let (s, c) = g.range(0.0, 6.3).sin_cos();
                let k = g.range(0.01, 3.0);
                [
                    k * c,
                    -k * s,
                    0.0,
                    offset + g.range(-300.0, 300.0),
                    k * s,
                    k * c,
                    0.0,
                    g.range(-30.0, 30.0),
                    0.0,
                    0.0,
                    k,
                    offset * 0.5 + g.range(-300.0, 300.0),
                ]
            })
            .collect();
        let members: Vec<[f32; 6]> = placements
            .iter()
            .map(|m| member_box(m, blas_lo, blas_hi))
            .collect();
        // The proxy box as the compiler makes it: the union of the transformed bounds
        // (corner form, unpadded), padded less than the members pad themselves.
        let mut bounds = [f32::MAX, f32::MAX, f32::MAX, f32::MIN, f32::MIN, f32::MIN];
        for m in &placements {
            let b = motu_compile::proxy_clusters::transformed_box(m, blas_lo, blas_hi);
            for a in 0..3 {
                bounds[a] = bounds[a].min(b[a]);
                bounds[3 + a] = bounds[3 + a].max(b[3 + a]);
            }
        }
        let bounds = motu_compile::proxy_boxes::padded(bounds);
        for b in &members {
            match unpacked(&bounds, quantised(&bounds, b)) {
                None => always += 1,
                Some(q) => {
                    assert!(holds(&q, b), "case {case}: {q:?} does not hold {b:?}");
                    // Outward rounding costs at most two steps an axis.
                    let r = reference(&bounds);
                    if (0..3).all(|a| b[a] - q[a] <= 2.0 * r.1[a] + 2.0 * r.2) {
                        tight += 1;
                    }
                }
            }
        }
    }
    assert_eq!(always, 0, "a member inside its proxy box always quantises");
    assert!(tight > 0);
}

#[test]
fn what_cannot_be_quantised_always_runs_the_exact_test() {
    let bounds = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0];
    assert_eq!(quantised(&bounds, &[-5.0, 0.0, 0.0, 0.5, 0.5, 0.5]), ALWAYS);
    assert_eq!(quantised(&bounds, &[0.0, 0.0, 0.0, 0.5, 7.0, 0.5]), ALWAYS);
    assert_eq!(
        quantised(&bounds, &[f32::NAN, 0.0, 0.0, 0.5, 0.5, 0.5]),
        ALWAYS
    );
    let infinite = [0.0, 0.0, 0.0, f32::INFINITY, 1.0, 1.0];
    assert_eq!(
        quantised(&infinite, &[0.1, 0.1, 0.1, 0.5, 0.5, 0.5]),
        ALWAYS
    );
    // A degenerate (flat) proxy box still quantises what lies in it.
    let flat = [0.0, 2.0, 0.0, 1.0, 2.0, 1.0];
    let b = [0.25, 2.0, 0.25, 0.5, 2.0, 0.5];
    let q = unpacked(&flat, quantised(&flat, &b)).expect("quantised");
    assert!(holds(&q, &b));
    assert!(ALWAYS[0] as u8 > (ALWAYS[0] >> 24) as u8);
}
