//! Reducing pbrt colour values (rgb, xyz, blackbody, spectra) to linear RGB.
//!
//! These are approximations good enough for a base colour: spectra are averaged
//! over three 100 nm bands, blackbodies are normalised to a maximum of 1.

/// Convert CIE XYZ to linear sRGB (D65).
pub fn xyz_to_rgb(xyz: [f32; 3]) -> [f32; 3] {
    let [x, y, z] = xyz;
    [
        3.240_454_2 * x - 1.537_138_5 * y - 0.498_531_4 * z,
        -0.969_266 * x + 1.876_010_8 * y + 0.041_556 * z,
        0.055_643_4 * x - 0.204_025_9 * y + 1.057_225_2 * z,
    ]
}

/// Planck's law (arbitrary scale), wavelength in nm, temperature in kelvin.
fn planck(lambda_nm: f64, kelvin: f64) -> f64 {
    const C: f64 = 299_792_458.0;
    const H: f64 = 6.626_070_15e-34;
    const KB: f64 = 1.380_649e-23;
    let l = lambda_nm * 1e-9;
    (2.0 * H * C * C) / (l.powi(5) * ((H * C / (l * KB * kelvin)).exp() - 1.0))
}

/// Normalised RGB of a blackbody emitter at `kelvin` (max channel 1).
pub fn blackbody_rgb(kelvin: f32) -> [f32; 3] {
    if !(kelvin.is_finite() && kelvin > 0.0) {
        return [0.0; 3];
    }
    let band = |lo: f64| {
        (0..10)
            .map(|i| planck(lo + 5.0 + 10.0 * i as f64, f64::from(kelvin)))
            .sum::<f64>()
    };
    let rgb = [band(600.0), band(500.0), band(400.0)];
    let max = rgb.iter().cloned().fold(0.0, f64::max);
    if !(max.is_finite() && max > 0.0) {
        return [0.0; 3];
    }
    rgb.map(|c| (c / max) as f32)
}

/// Average a piecewise-linear spectrum given as `(lambda_nm, value)` pairs over the
/// blue (400-500), green (500-600) and red (600-700 nm) bands.
pub fn spectrum_rgb(pairs: &[(f32, f32)]) -> Option<[f32; 3]> {
    if pairs.is_empty() {
        return None;
    }
    let mut sorted: Vec<(f32, f32)> = pairs
        .iter()
        .copied()
        .filter(|(l, v)| l.is_finite() && v.is_finite())
        .collect();
    if sorted.is_empty() {
        return None;
    }
    sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
    let eval = |l: f32| -> f32 {
        let i = sorted.partition_point(|p| p.0 < l);
        if i == 0 {
            return sorted[0].1;
        }
        if i >= sorted.len() {
            return sorted[sorted.len() - 1].1;
        }
        let (l0, v0) = sorted[i - 1];
        let (l1, v1) = sorted[i];
        if l1 <= l0 {
            return v1;
        }
        v0 + (v1 - v0) * (l - l0) / (l1 - l0)
    };
    let band = |lo: f32| {
        (0..20)
            .map(|i| eval(lo + 2.5 + 5.0 * i as f32))
            .sum::<f32>()
            / 20.0
    };
    Some([band(600.0), band(500.0), band(400.0)])
}

/// Parse a `.spd` spectrum file body: whitespace-separated `lambda value` pairs, `#` comments.
pub fn parse_spd(text: &[u8]) -> Option<Vec<(f32, f32)>> {
    let text = std::str::from_utf8(text).ok()?;
    let mut nums = Vec::new();
    for line in text.lines() {
        let line = line.split('#').next().unwrap_or("");
        for w in line.split_ascii_whitespace() {
            nums.push(w.parse::<f32>().ok()?);
        }
    }
    if nums.len() < 2 || nums.len() % 2 != 0 {
        return None;
    }
    Some(nums.chunks_exact(2).map(|c| (c[0], c[1])).collect())
}

#[cfg(test)]
mod tests;
