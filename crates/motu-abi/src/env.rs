//! Environment maps as lights: an `infinite` light's image, importance-sampled with a
//! piecewise-constant 2D distribution over its texels (pbrt-v3's `InfiniteAreaLight`: the
//! sampling function is each texel's luminance × sin θ of its row, so the sample density
//! follows the light that arrives, and the pole rows' smaller solid angle). The map is in
//! latitude-longitude form (pbrt-v3's `mapname`): row 0 is the light space's +z pole
//! (θ = 0), `u = φ / 2π` with `φ = atan2(y, x)`.
//!
//! Both renderers sample the same tables: the CPU reads [`Environment`] directly, the GPU
//! the words of [`Environment::gpu_words`] (`shaders/shade.glsl` `env_*`, mirrored line by
//! line). The tables are built here once, so the CDFs both search are bit-identical and only
//! the trigonometry differs by rounding.

use std::f32::consts::PI;
use std::sync::Mutex;

/// Words of the GPU header before the tables: width, height, sampleable, pad, then
/// `light_from_world` and `world_from_light` as three vec4 rows each.
pub const ENV_HEADER_WORDS: usize = 28;

/// An environment map ready to light with.
#[derive(Clone, PartialEq)]
pub struct Environment {
    width: u32,
    height: u32,
    /// Linear RGB radiance per texel (pbrt's `L` × `scale` applied), row-major, row 0 at θ = 0.
    radiance: Vec<[f32; 3]>,
    /// Rows of the rotation taking world directions into the map's space.
    light_from_world: [[f32; 3]; 3],
    world_from_light: [[f32; 3]; 3],
    /// Marginal CDF over rows (`height + 1` values, 0 to 1).
    marginal: Vec<f32>,
    /// Per row, the conditional CDF over its columns (`width + 1` values each).
    conditional: Vec<f32>,
    /// The map holds light to sample (its sampling function integrates above 0).
    sampleable: bool,
}

impl std::fmt::Debug for Environment {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "Environment({}×{}, sampleable: {})",
            self.width, self.height, self.sampleable
        )
    }
}

/// A sampled direction towards the environment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EnvSample {
    /// Unit world direction towards the light.
    pub world_dir: [f32; 3],
    pub radiance: [f32; 3],
    /// Density per solid angle.
    pub pdf: f32,
}

fn luminance(c: [f32; 3]) -> f32 {
    0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
}

fn mat_vec(m: &[[f32; 3]; 3], v: [f32; 3]) -> [f32; 3] {
    std::array::from_fn(|i| m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2])
}

fn normalize(v: [f32; 3]) -> [f32; 3] {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if l > 0.0 {
        v.map(|c| c / l)
    } else {
        v
    }
}

/// Builds `cdf` (n + 1 values) from `func` (n values); a function without mass gets the
/// uniform CDF. Returns the function's integral over [0, 1].
fn build_cdf(func: &[f64], cdf: &mut Vec<f32>) -> f64 {
    let n = func.len();
    let mut acc = vec![0.0f64; n + 1];
    for i in 0..n {
        acc[i + 1] = acc[i] + func[i] / n as f64;
    }
    let total = acc[n];
    for (i, a) in acc.iter().enumerate() {
        cdf.push(if total > 0.0 {
            (a / total) as f32
        } else {
            i as f32 / n as f32
        });
    }
    if let Some(last) = cdf.last_mut() {
        *last = 1.0;
    }
    total
}

/// The largest `i < n` with `cdf[i] <= u` (`cdf` has n + 1 values): the interval holding `u`.
/// The GLSL's `env_find` is this loop.
pub fn find_interval(cdf: &[f32], u: f32) -> usize {
    let n = cdf.len() - 1;
    let (mut lo, mut hi) = (0usize, n + 1);
    while lo < hi {
        let mid = (lo + hi) / 2;
        if cdf[mid] <= u {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    lo.saturating_sub(1).min(n - 1)
}

impl Environment {
    /// A `width × height` latitude-longitude map of linear radiance oriented by
    /// `world_from_light` (rows of a 3×3 rotation; a scale in it is normalised away).
    /// `None` for an empty map or a non-invertible orientation.
    pub fn new(
        width: u32,
        height: u32,
        radiance: Vec<[f32; 3]>,
        world_from_light: [[f32; 3]; 3],
    ) -> Option<Self> {
        if width == 0 || height == 0 || radiance.len() != width as usize * height as usize {
            return None;
        }
        let m = glam::Mat3::from_cols_array_2d(&world_from_light).transpose();
        if !m.is_finite() || m.determinant().abs() < 1e-12 {
            return None;
        }
        // Orthonormal (Gram-Schmidt), so the inverse is the transpose and both sides agree.
        let x = m.x_axis.normalize();
        let y = (m.y_axis - x * x.dot(m.y_axis)).normalize();
        let z = x.cross(y) * m.z_axis.dot(x.cross(y)).signum();
        let w = glam::Mat3::from_cols(x, y, z);
        let l = w.transpose();
        let rows = |m: glam::Mat3| {
            let t = m.transpose();
            [
                t.x_axis.to_array(),
                t.y_axis.to_array(),
                t.z_axis.to_array(),
            ]
        };
        let radiance: Vec<[f32; 3]> = radiance
            .into_iter()
            .map(|c| c.map(|v| if v.is_finite() { v.max(0.0) } else { 0.0 }))
            .collect();
        let (wu, hu) = (width as usize, height as usize);
        let mut conditional = Vec::with_capacity(hu * (wu + 1));
        let mut row_totals = Vec::with_capacity(hu);
        for r in 0..hu {
            let sin_theta = (PI * (r as f32 + 0.5) / height as f32).sin() as f64;
            let func: Vec<f64> = radiance[r * wu..(r + 1) * wu]
                .iter()
                .map(|&c| luminance(c) as f64 * sin_theta)
                .collect();
            row_totals.push(build_cdf(&func, &mut conditional));
        }
        let mut marginal = Vec::with_capacity(hu + 1);
        let total = build_cdf(&row_totals, &mut marginal);
        Some(Self {
            width,
            height,
            radiance,
            light_from_world: rows(l),
            world_from_light: rows(w),
            marginal,
            conditional,
            sampleable: total > 0.0 && total.is_finite(),
        })
    }

    pub fn width(&self) -> u32 {
        self.width
    }

    pub fn height(&self) -> u32 {
        self.height
    }

    /// Whether the map has light to sample.
    pub fn sampleable(&self) -> bool {
        self.sampleable
    }

    /// The map's mean radiance (a constant stand-in, e.g. for a streamed pixel's fallback).
    pub fn average(&self) -> [f32; 3] {
        let mut s = [0.0f64; 3];
        for c in &self.radiance {
            for i in 0..3 {
                s[i] += c[i] as f64;
            }
        }
        s.map(|v| (v / self.radiance.len().max(1) as f64) as f32)
    }

    fn texel(&self, col: usize, row: usize) -> [f32; 3] {
        self.radiance[row * self.width as usize + col]
    }

    /// Radiance arriving from unit world direction `d` (bilinear between texel centres,
    /// wrapping in φ): what a camera ray that escapes shows.
    pub fn radiance_towards(&self, d: [f32; 3]) -> [f32; 3] {
        let l = mat_vec(&self.light_from_world, normalize(d));
        let theta = l[2].clamp(-1.0, 1.0).acos();
        let mut phi = l[1].atan2(l[0]);
        if phi < 0.0 {
            phi += 2.0 * PI;
        }
        let x = phi / (2.0 * PI) * self.width as f32 - 0.5;
        let y = (theta / PI * self.height as f32 - 0.5).clamp(0.0, (self.height - 1) as f32);
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let w = self.width as i64;
        let col = |c: i64| c.rem_euclid(w) as usize;
        let (c0, c1) = (col(x0 as i64), col(x0 as i64 + 1));
        let r0 = y0 as usize;
        let r1 = (r0 + 1).min(self.height as usize - 1);
        let (a, b, c, e) = (
            self.texel(c0, r0),
            self.texel(c1, r0),
            self.texel(c0, r1),
            self.texel(c1, r1),
        );
        std::array::from_fn(|i| {
            let top = a[i] + (b[i] - a[i]) * fx;
            let bottom = c[i] + (e[i] - c[i]) * fx;
            top + (bottom - top) * fy
        })
    }

    /// A direction drawn from the map's distribution with two uniform numbers; `None` where
    /// the map has no light or the sample falls on a pole.
    pub fn sample(&self, u0: f32, u1: f32) -> Option<EnvSample> {
        if !self.sampleable {
            return None;
        }
        let (w, h) = (self.width as usize, self.height as usize);
        let row = find_interval(&self.marginal, u1);
        let (m0, m1) = (self.marginal[row], self.marginal[row + 1]);
        let dv = (u1 - m0) / (m1 - m0);
        let cdf = &self.conditional[row * (w + 1)..(row + 1) * (w + 1)];
        let col = find_interval(cdf, u0);
        let (c0, c1) = (cdf[col], cdf[col + 1]);
        let du = (u0 - c0) / (c1 - c0);
        let pdf_uv = h as f32 * (m1 - m0) * (w as f32 * (c1 - c0));
        let v = (row as f32 + dv) / h as f32;
        let u = (col as f32 + du) / w as f32;
        let theta = v * PI;
        let phi = u * 2.0 * PI;
        let sin_theta = theta.sin();
        if !(pdf_uv > 0.0 && sin_theta > 0.0) {
            return None;
        }
        let l = [sin_theta * phi.cos(), sin_theta * phi.sin(), theta.cos()];
        Some(EnvSample {
            world_dir: normalize(mat_vec(&self.world_from_light, l)),
            radiance: self.texel(col, row),
            pdf: pdf_uv / (2.0 * PI * PI * sin_theta),
        })
    }

    /// The tables as the GPU reads them (`shade.glsl` `env_*`): the header
    /// ([`ENV_HEADER_WORDS`]), the marginal CDF, the conditional CDFs, then RGB radiance.
    pub fn gpu_words(&self) -> Vec<u32> {
        let mut out = vec![self.width, self.height, u32::from(self.sampleable), 0];
        for m in [&self.light_from_world, &self.world_from_light] {
            for r in m {
                out.extend(r.iter().map(|v| v.to_bits()));
                out.push(0);
            }
        }
        debug_assert_eq!(out.len(), ENV_HEADER_WORDS);
        out.extend(self.marginal.iter().map(|v| v.to_bits()));
        out.extend(self.conditional.iter().map(|v| v.to_bits()));
        out.extend(self.radiance.iter().flatten().map(|v| v.to_bits()));
        out
    }

    /// Keeps `self` for the rest of the process and returns a `'static` reference to it (one
    /// per distinct map: equal maps share it), so the frame's `Shading` stays `Copy`.
    pub fn intern(self) -> &'static Environment {
        static KEPT: Mutex<Vec<&'static Environment>> = Mutex::new(Vec::new());
        let mut kept = KEPT.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(e) = kept.iter().find(|e| ***e == self) {
            return e;
        }
        let e: &'static Environment = Box::leak(Box::new(self));
        kept.push(e);
        e
    }
}

#[cfg(test)]
mod tests;
