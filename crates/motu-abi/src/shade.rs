//! The shading rules shared by the GPU (`shaders/shade.glsl`) and the CPU renderer
//! (`motu-trace`): light and texture records, the frame's light list, the per-pixel random
//! numbers, texture addressing and the tone map. The GLSL mirrors these functions line by
//! line; integer parts (hashes, texel addressing, mip selection) are bit-identical, floating
//! parts agree to rounding.

use bytemuck::{Pod, Zeroable};

/// Light kinds of [`LightRecord::kind`].
pub const LIGHT_DISTANT: u32 = 0;
pub const LIGHT_POINT: u32 = 1;
pub const LIGHT_SPOT: u32 = 2;
/// An emitting shape lit as a point at its centre; shadow rays stop `cos_total` (its bounding
/// radius) short of it so the emitter does not shadow its own light.
pub const LIGHT_AREA: u32 = 3;

/// Lights a frame shades with (the brightest ones; the rest are dropped with a warning).
pub const MAX_LIGHTS: usize = 8;

/// Coverage below which an alpha-tested surface is cut out.
pub const ALPHA_CUTOFF: f32 = 0.5;

/// A light of the frame. Distant lights carry irradiance (`radiance` = pbrt `L` × `scale`,
/// arriving perpendicular); point and spot lights carry intensity (`I` × `scale`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct LightRecord {
    pub world_position: [f32; 3],
    pub kind: u32,
    /// Unit direction the light travels (distant, spot).
    pub world_direction: [f32; 3],
    /// Spot: cosine of the half-angle where the cone ends. Area: the emitter's bounding radius.
    pub cos_total: f32,
    pub radiance: [f32; 3],
    /// Spot: cosine of the half-angle where falloff starts.
    pub cos_falloff: f32,
}

/// One image texture: a mip chain of RGBA8 texels, level 0 first, each level right after the
/// previous one in [`crate::HierarchyView::texels`]; `mip_count == 0` marks a Ptex texture
/// (faces, not a chain: [`crate::ptex`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct TextureRecord {
    /// Index of level 0's first texel.
    pub texel_offset: u32,
    pub width: u32,
    pub height: u32,
    pub mip_count: u32,
}

impl TextureRecord {
    /// Texels of the whole chain (a Ptex texture's: its words, [`crate::ptex`]).
    pub fn texel_count(&self) -> u64 {
        if self.mip_count == 0 {
            return u64::from(self.width);
        }
        (0..self.mip_count)
            .map(|l| mip_extent(self.width, l) as u64 * mip_extent(self.height, l) as u64)
            .sum()
    }
}

/// Extent of mip level `level` of an axis of `size` texels.
pub fn mip_extent(size: u32, level: u32) -> u32 {
    (size >> level.min(31)).max(1)
}

/// How a frame is lit and sampled (both renderers take it as is).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shading {
    /// The scene's lights; with none, the renderer's key light (its `sun_*` options) is used.
    pub lights: [LightRecord; MAX_LIGHTS],
    pub light_count: u32,
    /// Sky radiance for the ambient term (an infinite light's colour); `None`: the renderer's
    /// `ambient` grey.
    pub sky: Option<[f32; 3]>,
    /// Ambient-occlusion rays per sample (0: the sky term is unoccluded).
    pub ao_samples: u32,
    /// Farthest an occluder counts for ambient occlusion, world units.
    pub ao_distance: f32,
    /// Samples per pixel (the first at the pixel centre gives the hit record).
    pub spp: u32,
    /// Index of the frame's first sample in the pixel's sequence ([`crate::sampling`]): a
    /// progressive renderer (the viewer at rest) draws samples `first_sample..first_sample +
    /// spp` each frame and averages the frames. Only sample 0 is the pixel centre; a frame
    /// starting later writes its first sample's hit as the AOV record.
    pub first_sample: u32,
    /// Exposure in stops (the image is scaled by 2^ev before the sRGB transfer).
    pub exposure_ev: f32,
    /// Exposure from the image's log-average luminance ([`auto_exposure_ev`]) instead of
    /// `exposure_ev`: the renderers write linear RGB9E5 pixels ([`encode_rgb9e5`]) and
    /// [`resolve_auto_exposure`] tone-maps them once the whole image is known.
    pub auto_exposure: bool,
    /// The scene's environment map (an `infinite` light's image): importance-sampled by the
    /// sky term's rays and shown where camera rays escape; `None`: the constant `sky`.
    pub environment: Option<&'static crate::env::Environment>,
    /// Diffuse bounces after each camera hit, each vertex lit like the first (its lights'
    /// shadow rays, the environment's rays); 0: direct light only.
    pub bounces: u32,
}

impl Default for Shading {
    fn default() -> Self {
        Self {
            lights: [LightRecord::default(); MAX_LIGHTS],
            light_count: 0,
            sky: None,
            ao_samples: 0,
            ao_distance: f32::INFINITY,
            spp: 1,
            first_sample: 0,
            exposure_ev: 0.0,
            auto_exposure: false,
            environment: None,
            bounces: 0,
        }
    }
}

impl Shading {
    /// The lights to shade with: the scene's, else one distant key light towards `sun_dir`
    /// whose Lambertian response is `sun_intensity × N·L` (irradiance π × intensity).
    pub fn frame_lights(
        &self,
        sun_dir: [f32; 3],
        sun_intensity: f32,
    ) -> ([LightRecord; MAX_LIGHTS], u32) {
        if self.light_count > 0 {
            return (self.lights, self.light_count.min(MAX_LIGHTS as u32));
        }
        let l = (sun_dir[0] * sun_dir[0] + sun_dir[1] * sun_dir[1] + sun_dir[2] * sun_dir[2])
            .sqrt()
            .max(1e-20);
        let mut lights = [LightRecord::default(); MAX_LIGHTS];
        lights[0] = LightRecord {
            kind: LIGHT_DISTANT,
            world_direction: sun_dir.map(|c| -c / l),
            radiance: [sun_intensity * std::f32::consts::PI; 3],
            ..Default::default()
        };
        (lights, 1)
    }

    /// Sky radiance: the scene's, else `ambient` grey.
    pub fn sky_radiance(&self, ambient: f32) -> [f32; 3] {
        self.sky.unwrap_or([ambient; 3])
    }

    /// `2^exposure_ev`.
    pub fn exposure_scale(&self) -> f32 {
        self.exposure_ev.exp2()
    }
}

/// Middle grey: the log-average luminance auto exposure maps the image to (Reinhard's key).
pub const AUTO_EXPOSURE_KEY: f32 = 0.18;
/// Auto exposure stays within ±this many stops.
pub const AUTO_EXPOSURE_MAX_EV: f32 = 16.0;

/// Linear RGB as the shared-exponent RGB9E5 word (9-bit mantissas, 5-bit exponent, bias 15;
/// negative and NaN channels are 0, large ones clamp): what a shaded pixel holds until
/// [`resolve_auto_exposure`] tone-maps it. The GLSL's `encode_rgb9e5` is this function.
pub fn encode_rgb9e5(c: [f32; 3]) -> u32 {
    const MAX: f32 = 65408.0; // (511 / 512) × 2^16
    let c = c.map(|v| if v > 0.0 { v.min(MAX) } else { 0.0 });
    let m = c[0].max(c[1]).max(c[2]);
    if m <= 0.0 {
        return 0;
    }
    // floor(log2(m)) from the bits: exact, and identical on the GPU.
    let floor_log2 = ((m.to_bits() >> 23) & 0xff) as i32 - 127;
    let mut e = floor_log2.max(-16) + 16; // shared exponent, biased: 0..=31
    let mut denom = ((e - 15 - 9) as f32).exp2();
    if (m / denom + 0.5).floor() >= 512.0 {
        e += 1;
        denom *= 2.0;
    }
    let q = c.map(|v| ((v / denom + 0.5).floor() as u32).min(511));
    q[0] | q[1] << 9 | q[2] << 18 | (e as u32) << 27
}

/// The linear RGB an RGB9E5 word holds.
pub fn decode_rgb9e5(w: u32) -> [f32; 3] {
    let scale = (((w >> 27) as i32) - 15 - 9) as f32;
    let scale = scale.exp2();
    [w & 511, (w >> 9) & 511, (w >> 18) & 511].map(|m| m as f32 * scale)
}

/// Rec. 709 luminance of linear RGB.
pub fn luminance(c: [f32; 3]) -> f32 {
    0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
}

/// The exposure (stops) that maps the image's log-average luminance to
/// [`AUTO_EXPOSURE_KEY`] (Reinhard et al. 2002), over the pixels that hold light: a black
/// pixel carries no exposure information, and with one noisy sample a pixel (a path that
/// found no light) those would drag the average down until every lit pixel clips. An image
/// without light keeps 0.
pub fn auto_exposure_ev(pixels: impl Iterator<Item = [f32; 3]>) -> f32 {
    exposure_ev_of_logs(pixels.filter_map(log_luminance))
}

/// One pixel's term of [`auto_exposure_ev`]'s log average: the log of its luminance, or `None`
/// for a pixel without light. Callers that compute the terms in parallel pass them to
/// [`exposure_ev_of_logs`] in pixel order, so their exposure is [`auto_exposure_ev`]'s to the bit.
pub fn log_luminance(c: [f32; 3]) -> Option<f64> {
    let l = luminance(c);
    (l > 1e-6).then(|| (l as f64).ln())
}

/// [`auto_exposure_ev`] from the lit pixels' [`log_luminance`]s, summed in the order given.
pub fn exposure_ev_of_logs(logs: impl IntoIterator<Item = f64>) -> f32 {
    let (mut sum, mut n) = (0.0f64, 0u64);
    for l in logs {
        sum += l;
        n += 1;
    }
    if n == 0 {
        return 0.0;
    }
    let avg = (sum / n as f64).exp();
    let ev = (AUTO_EXPOSURE_KEY as f64 / avg).log2() as f32;
    ev.clamp(-AUTO_EXPOSURE_MAX_EV, AUTO_EXPOSURE_MAX_EV)
}

/// Tone-maps an image of RGB9E5 pixels (`rgba8`, 4 bytes a pixel, as the renderers wrote them
/// under auto exposure) in place with the exposure [`auto_exposure_ev`] picks for it, and
/// returns that exposure in stops.
pub fn resolve_auto_exposure(rgba8: &mut [u8]) -> f32 {
    let word = |p: &[u8]| u32::from_le_bytes([p[0], p[1], p[2], p[3]]);
    let ev = auto_exposure_ev(rgba8.chunks_exact(4).map(|p| decode_rgb9e5(word(p))));
    let scale = ev.exp2();
    for p in rgba8.chunks_exact_mut(4) {
        let c = tone_map(decode_rgb9e5(word(p)), scale);
        p[..3].copy_from_slice(&c);
        p[3] = 255;
    }
    ev
}

/// Phong exponent of a perceptual roughness (the specular lobe of both renderers).
pub fn shininess(roughness: f32) -> f32 {
    let a = (roughness * roughness).max(1e-3);
    (2.0 / (a * a) - 2.0).clamp(1.0, 4096.0)
}

/// Cosine-weighted direction about unit `n` from two uniform numbers (Duff et al.'s
/// branchless orthonormal basis).
pub fn cosine_direction(n: [f32; 3], u1: f32, u2: f32) -> [f32; 3] {
    let sign = if n[2] >= 0.0 { 1.0f32 } else { -1.0 };
    let a = -1.0 / (sign + n[2]);
    let b = n[0] * n[1] * a;
    let t = [1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0]];
    let bt = [b, sign + n[1] * n[1] * a, -n[1]];
    let r = u1.sqrt();
    let phi = 2.0 * std::f32::consts::PI * u2;
    let (x, y) = (r * phi.cos(), r * phi.sin());
    let z = (1.0 - u1).max(0.0).sqrt();
    std::array::from_fn(|i| x * t[i] + y * bt[i] + z * n[i])
}

/// A uniform number in [0, 1) for pixel `pixel`, sample `sample` (`sample | vertex << 20`),
/// dimension `dim`: the pixel's Owen-scrambled Sobol sequence ([`crate::sampling`]; identical
/// on the GPU).
pub fn rand01(pixel: u32, sample: u32, dim: u32) -> f32 {
    crate::sampling::sample01(pixel, sample, dim)
}

/// sRGB-encoded 8-bit value to linear.
pub fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.040_45 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// The mip level for a footprint of `texels_per_pixel` level-0 texels (rounded down, clamped).
pub fn mip_level(texels_per_pixel: f32, mip_count: u32) -> u32 {
    // NaN and footprints of at most one texel take the finest level.
    if texels_per_pixel.is_nan() || texels_per_pixel <= 1.0 {
        return 0;
    }
    (texels_per_pixel.log2().floor() as u32).min(mip_count.saturating_sub(1))
}

/// Bilinear sample (wrapping) of level `level` of `tex` at `uv`, linear RGBA (colour channels
/// decoded from sRGB, alpha as stored). `v` = 0 is the image's bottom row (pbrt's convention).
pub fn sample_texture(tex: &TextureRecord, texels: &[u32], uv: [f32; 2], level: u32) -> [f32; 4] {
    let level = level.min(tex.mip_count.saturating_sub(1));
    let mut base = tex.texel_offset as usize;
    for l in 0..level {
        base += mip_extent(tex.width, l) as usize * mip_extent(tex.height, l) as usize;
    }
    let (w, h) = (mip_extent(tex.width, level), mip_extent(tex.height, level));
    let uv = if uv.iter().all(|c| c.is_finite()) {
        uv
    } else {
        [0.0; 2]
    };
    let x = (uv[0] - uv[0].floor()) * w as f32 - 0.5;
    let y = (1.0 - (uv[1] - uv[1].floor())) * h as f32 - 0.5;
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let wrap = |v: i64, n: u32| v.rem_euclid(n as i64) as usize;
    let fetch = |xi: i64, yi: i64| -> [f32; 4] {
        let t = texels
            .get(base + wrap(yi, h) * w as usize + wrap(xi, w))
            .copied()
            .unwrap_or(0xff80_8080);
        let c = |s: u32| ((t >> s) & 0xff) as f32 / 255.0;
        [
            srgb_to_linear(c(0)),
            srgb_to_linear(c(8)),
            srgb_to_linear(c(16)),
            c(24),
        ]
    };
    let (xi, yi) = (x0 as i64, y0 as i64);
    let (a, b, c, d) = (
        fetch(xi, yi),
        fetch(xi + 1, yi),
        fetch(xi, yi + 1),
        fetch(xi + 1, yi + 1),
    );
    std::array::from_fn(|i| {
        let top = a[i] + (b[i] - a[i]) * fx;
        let bottom = c[i] + (d[i] - c[i]) * fx;
        top + (bottom - top) * fy
    })
}

/// Exposure and the sRGB transfer (values above 1 after exposure clip).
pub fn tone_map(c: [f32; 3], exposure_scale: f32) -> [u8; 3] {
    c.map(|v| {
        let v = (v * exposure_scale).clamp(0.0, 1.0);
        let s = if v <= 0.003_130_8 {
            12.92 * v
        } else {
            1.055 * v.powf(1.0 / 2.4) - 0.055
        };
        (s * 255.0 + 0.5) as u8
    })
}

#[cfg(test)]
mod tests;
