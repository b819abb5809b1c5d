//! Shading of one hit, the CPU mirror of `shaders/shade.glsl` (same rules, same random
//! numbers): shading normal (interpolated vertex normals), base colour × image texture
//! (mip level from the pixel footprint), the frame's lights with shadow rays, and the sky
//! term with ambient occlusion.

use motu_abi::camera::CameraParams;
use motu_abi::lod::{LodParams, RAY_SHADOW};
use motu_abi::shade::{
    cosine_direction, mip_level, rand01, sample_texture, shininess, LightRecord, LIGHT_AREA,
    LIGHT_DISTANT, LIGHT_SPOT, MAX_LIGHTS,
};
use motu_abi::{xform_point, FLAG_HAS_NORMALS, FLAG_HAS_UVS, NONE_U32};

pub use crate::coverage::coverage;
use crate::options::RenderOptions;
use crate::ray::shadow_offset;
use crate::ray::{cross, dot, invert, length, normalize, sub, transpose_vector};
use crate::traverse::{Hit, RayQuery, Scratch, Tracer};

/// Where a ray hit, ready to shade.
#[derive(Clone, Copy, Debug)]
pub struct SurfacePoint {
    pub world_position: [f32; 3],
    /// Geometric normal, facing the ray's origin.
    pub geometric_normal: [f32; 3],
    /// Interpolated vertex normal (the geometric one without), on the same side.
    pub shading_normal: [f32; 3],
    pub uv: Option<[f32; 2]>,
    /// Level-0 texels of a unit-square texture one pixel covers (for mip selection).
    pub uv_per_pixel: f32,
}

/// Barycentric weights of `p` in triangle `v` (the projection onto its plane).
pub fn barycentrics(v: [[f32; 3]; 3], p: [f32; 3]) -> [f32; 3] {
    let (e0, e1, ep) = (sub(v[1], v[0]), sub(v[2], v[0]), sub(p, v[0]));
    let (d00, d01, d11) = (dot(e0, e0), dot(e0, e1), dot(e1, e1));
    let (d20, d21) = (dot(ep, e0), dot(ep, e1));
    let den = d00 * d11 - d01 * d01;
    if den == 0.0 {
        return [1.0, 0.0, 0.0];
    }
    let b1 = (d11 * d20 - d01 * d21) / den;
    let b2 = (d00 * d21 - d01 * d20) / den;
    [1.0 - b1 - b2, b1, b2]
}

/// The surface at `hit` of the ray `org + t·dir` (`dir` unit).
pub fn surface_point(
    tracer: &Tracer<'_>,
    camera: &CameraParams,
    hit: &Hit,
    org: [f32; 3],
    dir: [f32; 3],
) -> SurfacePoint {
    let p: [f32; 3] = std::array::from_fn(|i| org[i] + dir[i] * hit.t);
    let mut ng = hit.world_normal();
    if dot(ng, dir) > 0.0 {
        ng = ng.map(|v| -v);
    }
    let mut sp = SurfacePoint {
        world_position: p,
        geometric_normal: ng,
        shading_normal: ng,
        uv: None,
        uv_per_pixel: 0.0,
    };
    let rec = &tracer.view().meshes[hit.mesh_record as usize];
    let Some(mesh) = tracer.mesh_bvh(hit.mesh_record) else {
        return sp;
    };
    let Some(attrs) = mesh.attributes.as_deref() else {
        return sp;
    };
    let slot = hit.slot;
    let Some(tri) = mesh.tri_local.get(slot as usize).and_then(|&local| {
        attrs
            .indices
            .get(3 * local as usize..3 * local as usize + 3)
    }) else {
        return sp;
    };
    let v = mesh.tri_verts[slot as usize];
    let b = barycentrics(v, xform_point(&hit.object_from_world, p));
    let idx = [tri[0] as usize, tri[1] as usize, tri[2] as usize];
    if let (true, Some(n)) = (rec.flags & FLAG_HAS_NORMALS != 0, &attrs.normals) {
        let n_obj: [f32; 3] = std::array::from_fn(|a| {
            b[0] * n[idx[0]][a] + b[1] * n[idx[1]][a] + b[2] * n[idx[2]][a]
        });
        let ns = normalize(transpose_vector(&hit.object_from_world, n_obj));
        if ns.iter().all(|c| c.is_finite()) && length(ns) > 0.5 {
            sp.shading_normal = if dot(ns, ng) < 0.0 {
                ns.map(|c| -c)
            } else {
                ns
            };
        }
    }
    if let (true, Some(uv)) = (rec.flags & FLAG_HAS_UVS != 0, &attrs.uvs) {
        let t = [uv[idx[0]], uv[idx[1]], uv[idx[2]]];
        sp.uv = Some(std::array::from_fn(|a| {
            b[0] * t[0][a] + b[1] * t[1][a] + b[2] * t[2][a]
        }));
        if let Some(world_from_object) = invert(&hit.object_from_world) {
            let w = v.map(|x| xform_point(&world_from_object, x));
            let world_area = length(cross(sub(w[1], w[0]), sub(w[2], w[0])));
            let (du1, dv1) = (t[1][0] - t[0][0], t[1][1] - t[0][1]);
            let (du2, dv2) = (t[2][0] - t[0][0], t[2][1] - t[0][1]);
            let uv_area = (du1 * dv2 - du2 * dv1).abs();
            if world_area > 0.0 {
                sp.uv_per_pixel =
                    hit.t / camera.pixels_per_unit_at_1 * (uv_area / world_area).sqrt();
            }
        }
    }
    sp
}

/// The base colour of a hit under Ptex texture `tex` (`texture.glsl` `ptex_albedo`): the
/// face's sample at the face uv; `None` keeps the material's colour (a LOD level, whose
/// triangles are not the source mesh's, or a face the texture does not have).
fn ptex_albedo(
    tracer: &Tracer<'_>,
    hit: &Hit,
    sp: &SurfacePoint,
    tex: &motu_abi::TextureRecord,
) -> Option<[f32; 3]> {
    use motu_abi::ptex::{default_face_uv, ptex_face, sample_ptex};
    let view = tracer.view();
    if view.meshes.get(hit.mesh_record as usize)?.lod != 0 {
        return None;
    }
    let v = *tracer
        .mesh_bvh(hit.mesh_record)?
        .tri_verts
        .get(hit.slot as usize)?;
    let b = barycentrics(v, xform_point(&hit.object_from_world, sp.world_position));
    let (face, second_half) = ptex_face(tex, view.texels, hit.source_mesh, hit.primitive);
    let uv = sp.uv.unwrap_or_else(|| default_face_uv(b, second_half));
    sample_ptex(tex, view.texels, face, uv).map(|c| [c[0], c[1], c[2]])
}

/// The direction towards a light, its distance (shadow-ray length) and the irradiance it
/// brings at normal incidence; `None` where it brings nothing.
pub fn light_incidence(l: &LightRecord, p: [f32; 3]) -> Option<([f32; 3], f32, [f32; 3])> {
    if l.kind == LIGHT_DISTANT {
        let d = l.world_direction.map(|c| -c);
        return Some((d, f32::INFINITY, l.radiance));
    }
    let to = sub(l.world_position, p);
    let d2 = dot(to, to);
    if d2 <= 0.0 {
        return None;
    }
    let dist = d2.sqrt();
    let dir = to.map(|c| c / dist);
    let mut scale = 1.0 / d2;
    let mut reach = dist;
    if l.kind == LIGHT_SPOT {
        let c = -dot(dir, l.world_direction);
        let x = ((c - l.cos_total) / (l.cos_falloff - l.cos_total).max(1e-6)).clamp(0.0, 1.0);
        scale *= x * x * (3.0 - 2.0 * x);
    } else if l.kind == LIGHT_AREA {
        reach = dist - l.cos_total;
        if reach <= 0.0 {
            return None;
        }
    }
    if scale <= 0.0 {
        return None;
    }
    Some((dir, reach, l.radiance.map(|c| c * scale)))
}

/// Counts of the secondary rays one shading traced.
#[derive(Default)]
pub struct ShadeRays {
    pub rays: u64,
    pub traces: u32,
    pub max_stack: u32,
    /// A shading ray was cut short at `max_traces_per_ray`.
    pub truncated: bool,
}

/// Where a path may bounce from a shaded vertex (`shade.glsl` `bounce_ray`).
#[derive(Clone, Copy, Debug)]
pub struct BounceFrom {
    /// The offset start of rays leaving the vertex.
    pub start: [f32; 3],
    pub shading_normal: [f32; 3],
    pub geometric_normal: [f32; 3],
    /// Diffuse albedo: the throughput factor of a cosine-sampled Lambert bounce.
    pub diffuse: [f32; 3],
    pub lod: u32,
}

impl BounceFrom {
    /// The bounce's direction drawn with the next vertex's sample `next_sample` (dimensions 0
    /// and 1, which secondary rays never use); `None` below the surface or without a diffuse
    /// part.
    pub fn direction(&self, pixel: u32, next_sample: u32) -> Option<[f32; 3]> {
        let d = cosine_direction(
            self.shading_normal,
            rand01(pixel, next_sample, 0),
            rand01(pixel, next_sample, 1),
        );
        let peak = self.diffuse[0].max(self.diffuse[1]).max(self.diffuse[2]);
        (dot(d, self.geometric_normal) > 0.0 && peak > 0.0).then_some(d)
    }
}

/// Colour (linear, before exposure) of `hit` for sample `sample` of pixel `pixel`.
#[allow(clippy::too_many_arguments)]
pub fn shade_hit(
    tracer: &Tracer<'_>,
    camera: &CameraParams,
    opts: &RenderOptions,
    hit: &Hit,
    org: [f32; 3],
    dir: [f32; 3],
    pixel: u32,
    sample: u32,
    scratch: &mut Scratch,
    rays: &mut ShadeRays,
) -> [f32; 3] {
    shade_vertex(
        tracer, camera, opts, hit, org, dir, pixel, sample, true, scratch, rays,
    )
    .0
}

/// The hit's base colour under its material's texture (image or Ptex), as shading sees it
/// (`shade.glsl` `shade_input`): the albedo view and the denoiser's guide.
pub fn hit_albedo(
    tracer: &Tracer<'_>,
    camera: &CameraParams,
    hit: &Hit,
    org: [f32; 3],
    dir: [f32; 3],
) -> [f32; 3] {
    let view = tracer.view();
    let rec = &view.meshes[hit.mesh_record as usize];
    let mat = view
        .materials
        .get(rec.material as usize)
        .copied()
        .unwrap_or_default();
    let sp = surface_point(tracer, camera, hit, org, dir);
    textured_albedo(tracer, hit, &sp, &mat)
}

fn textured_albedo(
    tracer: &Tracer<'_>,
    hit: &Hit,
    sp: &SurfacePoint,
    mat: &motu_abi::MaterialRecord,
) -> [f32; 3] {
    let view = tracer.view();
    let mut albedo = mat.base_color;
    let texture = view.textures.get(mat.base_color_texture as usize);
    if let Some(tex) = texture.filter(|t| motu_abi::ptex::is_ptex(t)) {
        albedo = ptex_albedo(tracer, hit, sp, tex).unwrap_or(albedo);
    } else if let (Some(tex), Some(uv)) = (texture, sp.uv) {
        if mat.base_color_texture != NONE_U32 {
            let texels_per_pixel =
                sp.uv_per_pixel * ((tex.width as f32) * (tex.height as f32)).sqrt();
            let c = sample_texture(
                tex,
                view.texels,
                uv,
                mip_level(texels_per_pixel, tex.mip_count),
            );
            albedo = std::array::from_fn(|i| albedo[i] * c[i]);
        }
    }
    albedo
}

/// [`shade_hit`] for a vertex of a path: `emission` says whether the surface's own light
/// counts (the camera's hit; not after a bounce, whose light sources are sampled as lights).
/// Also returns where the path may bounce from.
#[allow(clippy::too_many_arguments)]
pub fn shade_vertex(
    tracer: &Tracer<'_>,
    camera: &CameraParams,
    opts: &RenderOptions,
    hit: &Hit,
    org: [f32; 3],
    dir: [f32; 3],
    pixel: u32,
    sample: u32,
    emission: bool,
    scratch: &mut Scratch,
    rays: &mut ShadeRays,
) -> ([f32; 3], BounceFrom) {
    let view = tracer.view();
    let rec = &view.meshes[hit.mesh_record as usize];
    let mat = view
        .materials
        .get(rec.material as usize)
        .copied()
        .unwrap_or_default();
    let sp = surface_point(tracer, camera, hit, org, dir);
    let albedo = textured_albedo(tracer, hit, &sp, &mat);
    let (ns, ng) = (sp.shading_normal, sp.geometric_normal);
    let diffuse = albedo.map(|c| c * (1.0 - mat.metallic));
    let f0: [f32; 3] = std::array::from_fn(|i| 0.04 + (albedo[i] - 0.04) * mat.metallic);
    let s = shininess(mat.roughness);
    let spec_norm = (s + 8.0) / (8.0 * std::f32::consts::PI);
    let reach = org[0].abs().max(org[1].abs()).max(org[2].abs()) + hit.t;
    let start = shadow_offset(sp.world_position, ng, reach);
    let q = RayQuery {
        kind: RAY_SHADOW,
        any_hit: true,
        lod: LodParams {
            forced_lod: if opts.shadow_lod_from_primary {
                hit.lod as i32
            } else {
                opts.lod.forced_lod
            },
            ..opts.lod
        },
        pixels_per_unit_at_1: camera.pixels_per_unit_at_1,
        max_traces: opts.max_traces_per_ray,
        ..RayQuery::default()
    };
    let mut occluded = |d: [f32; 3], t_max: f32, scratch: &mut Scratch| -> bool {
        let h = tracer.trace(start, d, &RayQuery { t_max, ..q }, scratch);
        rays.truncated |= h.truncated;
        rays.rays += 1;
        rays.traces += h.traces;
        rays.max_stack = rays.max_stack.max(h.max_stack);
        h.is_hit()
    };
    let mut colour = if emission { mat.emission } else { [0.0; 3] };
    let bounce = BounceFrom {
        start,
        shading_normal: ns,
        geometric_normal: ng,
        diffuse,
        lod: hit.lod,
    };
    let (lights, count) = opts
        .shading
        .frame_lights(opts.sun_dir_world, opts.sun_intensity);
    for l in lights.iter().take((count as usize).min(MAX_LIGHTS)) {
        let Some((ldir, dist, e)) = light_incidence(l, sp.world_position) else {
            continue;
        };
        let ndl = dot(ns, ldir);
        if ndl <= 0.0 || dot(ng, ldir) <= 0.0 {
            continue;
        }
        if opts.shadows && occluded(ldir, dist, scratch) {
            continue;
        }
        let h = normalize(sub(ldir, dir));
        let spec = spec_norm * dot(ns, h).max(0.0).powf(s);
        colour = std::array::from_fn(|i| {
            colour[i] + (diffuse[i] / std::f32::consts::PI + f0[i] * spec) * e[i] * ndl
        });
    }
    let sky = opts.shading.sky_radiance(opts.ambient);
    let mut ao = 1.0;
    let n_ao = opts.shading.ao_samples;
    if let (Some(env), true) = (opts.shading.environment, n_ao > 0) {
        // The environment map as a light: its rays are drawn from the map and reach to
        // infinity; each clear one adds the map's radiance through the material over its
        // density (`shade.glsl` `environment_term`).
        for k in 0..n_ao {
            let Some(smp) = env.sample(
                rand01(pixel, sample, 2 + 2 * k),
                rand01(pixel, sample, 3 + 2 * k),
            ) else {
                continue;
            };
            let d = smp.world_dir;
            let ndl = dot(ns, d);
            if dot(d, ng) <= 0.0 || ndl <= 0.0 || occluded(d, f32::INFINITY, scratch) {
                continue;
            }
            let h = normalize(sub(d, dir));
            let spec = spec_norm * dot(ns, h).max(0.0).powf(s);
            let w = ndl / (smp.pdf * n_ao as f32);
            colour = std::array::from_fn(|i| {
                colour[i] + (diffuse[i] / std::f32::consts::PI + f0[i] * spec) * smp.radiance[i] * w
            });
        }
        return (colour, bounce);
    }
    if n_ao > 0 {
        let mut open = 0u32;
        for k in 0..n_ao {
            let d = cosine_direction(
                ns,
                rand01(pixel, sample, 2 + 2 * k),
                rand01(pixel, sample, 3 + 2 * k),
            );
            if dot(d, ng) > 0.0 && !occluded(d, opts.shading.ao_distance, scratch) {
                open += 1;
            }
        }
        ao = open as f32 / n_ao as f32;
    }
    (
        std::array::from_fn(|i| colour[i] + (diffuse[i] + f0[i]) * sky[i] * ao),
        bounce,
    )
}
