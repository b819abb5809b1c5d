//! `--denoise` (and the viewer's `N` key): an edge-avoiding à-trous wavelet filter (Dammertz
//! et al. 2010, "Edge-Avoiding À-Trous Wavelet Transform for fast Global Illumination
//! Filtering") over the finished shaded image, on the host. Its guides are a G-buffer rebuilt
//! from what a render already has: the AOV's hit distance gives each pixel's world position
//! (along its centre ray) and, from its neighbours on the same mesh, a normal; the AOV's mesh
//! gives the material's base colour. Each pass blurs with the B3-spline kernel at a doubling
//! stride and weights every tap by how well it agrees in normal, plane distance, base colour
//! and colour, so the noise of a few samples goes while silhouettes, creases and material
//! edges stay. Where a material has a texture the base-colour guide is the textured colour at
//! the primary hit ([`add_texture_albedo`], from the same frame's `albedo` view on every
//! backend), so texel edges stay too. Pixels without a hit (the sky, the environment map) are left as they are and
//! never mixed into hits. The AOV itself is never touched.

use motu_abi::aov::{Aov, MISS};
use motu_abi::camera::CameraParams;

/// The filter's strengths; `Default` is what `--denoise` uses.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DenoiseOptions {
    /// À-trous passes (strides 1, 2, 4, ...): 5 reach 2 × 2^5 = 64 pixels across.
    pub iterations: u32,
    /// Exponent of the normal weight `max(0, n_p·n_q)^sigma_normal`.
    pub sigma_normal: f32,
    /// Plane-distance tolerance, in pixel footprints at the tap's distance.
    pub sigma_plane: f32,
    /// Base-colour tolerance (linear RGB distance).
    pub sigma_albedo: f32,
    /// Colour tolerance of the first pass (linear, exposed), halved each pass.
    pub sigma_colour: f32,
}

impl Default for DenoiseOptions {
    fn default() -> Self {
        Self {
            iterations: 5,
            sigma_normal: 64.0,
            sigma_plane: 1.0,
            sigma_albedo: 0.1,
            sigma_colour: 0.6,
        }
    }
}

/// One pixel of the guide: `depth` is infinite where the centre ray missed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GuidePixel {
    pub world_position: [f32; 3],
    pub normal: [f32; 3],
    pub albedo: [f32; 3],
    pub depth: f32,
}

impl GuidePixel {
    fn is_hit(&self) -> bool {
        self.depth.is_finite()
    }
}

/// The guide of an image from its AOV and camera; `albedo_of_mesh` gives a source mesh's base
/// colour (its material's constant).
pub fn guide_from_aov(
    aov: &Aov,
    camera: &CameraParams,
    albedo_of_mesh: impl Fn(u32) -> [f32; 3],
) -> Vec<GuidePixel> {
    let (w, h) = (aov.width as usize, aov.height as usize);
    let eye = camera.world_eye;
    let mut g: Vec<GuidePixel> = (0..w * h)
        .map(|i| {
            let r = &aov.records[i];
            if r.mesh == MISS || !r.t.is_finite() {
                return GuidePixel {
                    world_position: [0.0; 3],
                    normal: [0.0; 3],
                    albedo: [0.0; 3],
                    depth: f32::INFINITY,
                };
            }
            let d = camera
                .primary_dir((i % w) as u32, (i / w) as u32, 0.5, 0.5)
                .to_array();
            GuidePixel {
                world_position: std::array::from_fn(|a| eye[a] + r.t * d[a]),
                normal: d.map(|c| -c),
                albedo: albedo_of_mesh(r.mesh),
                depth: r.t,
            }
        })
        .collect();
    // Normals from the positions: on each axis the neighbour on the same mesh nearest in depth
    // (a one-sided difference never reaches across a silhouette), facing the camera.
    let normals: Vec<[f32; 3]> = (0..w * h)
        .map(|i| {
            let p = &g[i];
            if !p.is_hit() {
                return p.normal;
            }
            let (x, y) = (i % w, i / w);
            let mesh = aov.records[i].mesh;
            let pick = |a: Option<usize>, b: Option<usize>| {
                let ok = |j: Option<usize>| {
                    j.filter(|&j| aov.records[j].mesh == mesh && g[j].is_hit())
                        .map(|j| (j, (g[j].depth - p.depth).abs()))
                };
                match (ok(a), ok(b)) {
                    (Some((ja, da)), Some((jb, db))) => Some(if da <= db {
                        sub(g[ja].world_position, p.world_position)
                    } else {
                        sub(p.world_position, g[jb].world_position)
                    }),
                    (Some((ja, _)), None) => Some(sub(g[ja].world_position, p.world_position)),
                    (None, Some((jb, _))) => Some(sub(p.world_position, g[jb].world_position)),
                    (None, None) => None,
                }
            };
            let dx = pick((x + 1 < w).then(|| i + 1), (x > 0).then(|| i - 1));
            let dy = pick((y + 1 < h).then(|| i + w), (y > 0).then(|| i - w));
            let (Some(dx), Some(dy)) = (dx, dy) else {
                return p.normal;
            };
            let n = cross(dx, dy);
            let len = dot(n, n).sqrt();
            if len.is_nan() || len <= 0.0 {
                return p.normal;
            }
            let n = n.map(|c| c / len);
            // p.normal is still the reversed view direction here.
            if dot(n, p.normal) < 0.0 {
                n.map(|c| -c)
            } else {
                n
            }
        })
        .collect();
    for (p, n) in g.iter_mut().zip(normals) {
        p.normal = n;
    }
    g
}

/// Puts the textured base colour of each hit into `guide`: `albedo` is the same frame's
/// albedo view (`--view albedo`: sRGB, the primary hit's texture at its texel) and `albedo_aov`
/// its AOV. A pixel whose albedo-view hit is not the guide's (`aov`) keeps its material
/// constant. Without it a textured surface is one material to the filter, which then blurs
/// across its texel edges. Returns the pixels taken from the image.
pub fn add_texture_albedo(
    guide: &mut [GuidePixel],
    aov: &Aov,
    albedo: &[u8],
    albedo_aov: &Aov,
) -> u64 {
    assert_eq!(guide.len(), aov.records.len(), "guide and AOV disagree");
    if albedo_aov.records.len() != aov.records.len() || albedo.len() != guide.len() * 4 {
        return 0;
    }
    let mut taken = 0;
    for (i, g) in guide.iter_mut().enumerate() {
        let (a, b) = (&aov.records[i], &albedo_aov.records[i]);
        if g.is_hit() && a.mesh == b.mesh && a.primitive == b.primitive {
            let px = &albedo[i * 4..i * 4 + 3];
            g.albedo =
                std::array::from_fn(|c| motu_abi::shade::srgb_to_linear(f32::from(px[c]) / 255.0));
            taken += 1;
        }
    }
    taken
}

/// Whether any material of `view` has a base-colour texture (only then does the guide need the
/// albedo view).
pub fn has_textured_materials(view: &motu_abi::HierarchyView<'_>) -> bool {
    view.materials
        .iter()
        .any(|m| m.base_color_texture != motu_abi::NONE_U32)
}

/// What a denoise did (`denoise` in `--stats`: the JSON is [`crate::stats::DenoiseStats`]).
#[derive(Clone, Copy, Debug)]
pub struct DenoiseStats {
    pub filter: &'static str,
    pub iterations: u32,
    /// Pixels filtered (those with a hit).
    pub filtered_pixels: u64,
    pub denoise_ms: f64,
}

/// Filters the shaded image `rgba8` (sRGB, as written) in place with `guide`: the colours are
/// taken back to linear, filtered and encoded again; alpha is kept. `pixel_footprint` is the
/// angle one pixel spans (radians), the plane tolerance's unit.
pub fn denoise_rgba8(
    rgba8: &mut [u8],
    width: u32,
    height: u32,
    guide: &[GuidePixel],
    pixel_footprint: f32,
    opts: &DenoiseOptions,
) -> DenoiseStats {
    let t0 = std::time::Instant::now();
    let (w, h) = (width as usize, height as usize);
    assert_eq!(rgba8.len(), w * h * 4, "image and size disagree");
    assert_eq!(guide.len(), w * h, "guide and size disagree");
    let mut colour: Vec<[f32; 3]> = rgba8
        .chunks_exact(4)
        .map(|p| [p[0], p[1], p[2]].map(|v| motu_abi::shade::srgb_to_linear(f32::from(v) / 255.0)))
        .collect();
    if w == 0 || h == 0 {
        return DenoiseStats {
            filter: "a-trous",
            iterations: opts.iterations,
            filtered_pixels: 0,
            denoise_ms: 0.0,
        };
    }
    let mut next = colour.clone();
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(h.max(1));
    let rows_per = h.div_ceil(threads).max(1);
    for it in 0..opts.iterations {
        let pass = Pass {
            w,
            h,
            guide,
            colour: &colour,
            step: 1isize << it,
            sigma_c: opts.sigma_colour * 0.5f32.powi(it as i32),
            footprint: pixel_footprint,
            opts,
        };
        std::thread::scope(|scope| {
            for (k, rows) in next.chunks_mut(rows_per * w).enumerate() {
                let pass = &pass;
                scope.spawn(move || {
                    for (r, out) in rows.iter_mut().enumerate() {
                        *out = pass.filter(k * rows_per * w + r);
                    }
                });
            }
        });
        std::mem::swap(&mut colour, &mut next);
    }
    let mut filtered = 0u64;
    for ((px, c), g) in rgba8.chunks_exact_mut(4).zip(&colour).zip(guide) {
        if g.is_hit() {
            filtered += 1;
            let enc = motu_abi::shade::tone_map(*c, 1.0);
            px[..3].copy_from_slice(&enc);
        }
    }
    DenoiseStats {
        filter: "a-trous",
        iterations: opts.iterations,
        filtered_pixels: filtered,
        denoise_ms: t0.elapsed().as_secs_f64() * 1e3,
    }
}

/// One à-trous pass over the image: its stride and colour tolerance.
struct Pass<'a> {
    w: usize,
    h: usize,
    guide: &'a [GuidePixel],
    colour: &'a [[f32; 3]],
    step: isize,
    sigma_c: f32,
    footprint: f32,
    opts: &'a DenoiseOptions,
}

impl Pass<'_> {
    /// Pixel `i` after this pass: the B3-spline taps at the stride, each weighted by how
    /// well it agrees with the pixel in normal, plane, base colour and colour.
    fn filter(&self, i: usize) -> [f32; 3] {
        const KERNEL: [f32; 5] = [1.0 / 16.0, 1.0 / 4.0, 3.0 / 8.0, 1.0 / 4.0, 1.0 / 16.0];
        let (w, h, o) = (self.w, self.h, self.opts);
        let p = &self.guide[i];
        let cp = self.colour[i];
        if !p.is_hit() {
            return cp;
        }
        let (x, y) = ((i % w) as isize, (i / w) as isize);
        let mut sum = [0.0f32; 3];
        let mut wsum = 0.0f32;
        for (ky, hy) in KERNEL.iter().enumerate() {
            let qy = y + (ky as isize - 2) * self.step;
            if qy < 0 || qy >= h as isize {
                continue;
            }
            for (kx, hx) in KERNEL.iter().enumerate() {
                let qx = x + (kx as isize - 2) * self.step;
                if qx < 0 || qx >= w as isize {
                    continue;
                }
                let j = qy as usize * w + qx as usize;
                let q = &self.guide[j];
                if !q.is_hit() {
                    continue;
                }
                let wn = dot(p.normal, q.normal).max(0.0).powf(o.sigma_normal);
                let offset_px = (((qx - x).pow(2) + (qy - y).pow(2)) as f32).sqrt();
                let plane = dot(p.normal, sub(q.world_position, p.world_position)).abs();
                let scale = o.sigma_plane * self.footprint * p.depth * offset_px.max(1.0);
                let wp = (-plane / scale.max(1e-20)).exp();
                let wa = (-dist2(p.albedo, q.albedo) / (o.sigma_albedo * o.sigma_albedo)).exp();
                let wc =
                    (-dist2(cp, self.colour[j]) / (self.sigma_c * self.sigma_c).max(1e-12)).exp();
                let wt = hx * hy * wn * wp * wa * wc;
                for (s, c) in sum.iter_mut().zip(self.colour[j]) {
                    *s += wt * c;
                }
                wsum += wt;
            }
        }
        // The centre tap always weighs (3/8)² × 1, so wsum > 0.
        sum.map(|s| s / wsum)
    }
}

/// The base colour of each source mesh (its material's constant; the first compiled mesh of
/// it decides): the denoiser's material guide.
pub fn mesh_base_colours(
    view: &motu_abi::HierarchyView<'_>,
) -> std::collections::HashMap<u32, [f32; 3]> {
    let mut albedo = std::collections::HashMap::new();
    for m in view.meshes {
        let colour = view
            .materials
            .get(m.material as usize)
            .map_or([0.5; 3], |mat| mat.base_color);
        albedo.entry(m.source_mesh).or_insert(colour);
    }
    albedo
}

/// The angle one pixel of `camera` spans at the image's centre (radians).
pub fn pixel_footprint(camera: &CameraParams) -> f32 {
    let (cx, cy) = (camera.width / 2, camera.height / 2);
    let a = camera.primary_dir(cx, cy, 0.0, 0.5);
    let b = camera.primary_dir(cx, cy, 1.0, 0.5);
    (b - a).length().max(1e-9)
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn dist2(a: [f32; 3], b: [f32; 3]) -> f32 {
    let d = sub(a, b);
    dot(d, d)
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[cfg(test)]
mod tests;
