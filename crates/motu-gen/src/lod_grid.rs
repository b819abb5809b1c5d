//! `lod-grid`: one dense bumpy sphere (a PLY of ~100k+ triangles) instanced
//! on a `W×H` grid that recedes from the camera, so the same mesh is seen
//! from a few units to hundreds of units away (standard single-level pbrt).

use std::f64::consts::TAU;
use std::path::Path;

use crate::math::{scale, Affine};
use crate::mesh::{write_ply, write_trianglemesh, ParamGrid, SineNoise, TriangleSource, UvSphere};
use crate::pbrt::{
    push_camera, push_film, push_instance, push_material, push_sun, CameraSpec, Syntax,
};
use crate::rng::{derive_seed, SplitMix64};
use crate::run::{run_jobs, Ctx, Job, Tally};
use crate::text::OutFile;
use crate::{GenError, GenProgress, GenSummary, GridSize};

/// Options of `motu gen lod-grid`.
#[derive(Clone, Debug, PartialEq)]
pub struct LodGridOptions {
    /// `width` copies across the view, `height` rows receding from the camera.
    pub grid: GridSize,
    /// Target triangle count of the dense mesh (rounded to the tessellation).
    pub triangles: u32,
    /// Distance between neighbouring copies (the mesh has radius ≈ 1).
    pub spacing: f64,
    pub seed: u64,
    pub width: u32,
    pub height: u32,
}

impl Default for LodGridOptions {
    fn default() -> Self {
        Self {
            grid: GridSize::new(16, 64),
            triangles: 120_000,
            spacing: 3.0,
            seed: 1,
            width: 640,
            height: 360,
        }
    }
}

fn dense_mesh(o: &LodGridOptions) -> impl TriangleSource {
    // 2·s·(s/2 − 1) ≈ s² triangles.
    let segments = (f64::from(o.triangles).sqrt().round() as u32).max(8);
    let noise = SineNoise::new(derive_seed(o.seed, &[4]), 6, 3.0);
    UvSphere::new(segments, segments / 2, move |d| {
        scale(d, 1.0 + 0.12 * noise.at(d))
    })
}

fn extent(o: &LodGridOptions) -> (f64, f64) {
    (
        f64::from(o.grid.width) * o.spacing,
        f64::from(o.grid.height) * o.spacing,
    )
}

pub(crate) fn generate(
    o: &LodGridOptions,
    root: &Path,
    progress: &mut dyn FnMut(GenProgress),
) -> Result<GenSummary, GenError> {
    if !(8..=100_000_000).contains(&o.triangles) {
        return Err(GenError::InvalidOption {
            option: "triangles",
            reason: "must be in 8..=100000000".into(),
        });
    }
    if !(o.spacing.is_finite() && o.spacing > 0.0) {
        return Err(GenError::InvalidOption {
            option: "spacing",
            reason: "must be a positive number".into(),
        });
    }
    if o.grid.count() > crate::forest::MAX_FLAT_INSTANCES || o.width == 0 || o.height == 0 {
        return Err(GenError::InvalidOption {
            option: "grid",
            reason: "grid and image must be non-empty and the grid at most 2^30 cells".into(),
        });
    }
    let dense = dense_mesh(o);
    let (ex, ez) = extent(o);
    let ground = ParamGrid::new(2, 2, false, move |u, v| {
        [(u - 0.5) * (ex + 20.0), 0.0, v * (ez + 20.0) - 10.0]
    });
    let dense_tris = u64::from(dense.triangle_count());
    let ground_tris = u64::from(ground.triangle_count());
    let dense_ref = &dense;
    let ground_ref = &ground;
    let jobs: Vec<Job<'_>> = vec![
        Box::new(move |ctx: &Ctx<'_>| {
            Ok(Tally::file(write_ply(
                ctx.root,
                "dense.ply",
                dense_ref,
                ctx.live,
            )?))
        }),
        Box::new(move |ctx: &Ctx<'_>| write_scene(o, ctx, ground_ref)),
    ];
    let tally = run_jobs(root, jobs, None, progress)?;
    let copies = o.grid.count();
    Ok(GenSummary {
        scene_path: root.join("scene.pbrt"),
        files_written: tally.files,
        bytes_written: tally.bytes,
        object_instances: tally.object_instances,
        flattened_instances: copies,
        unique_triangles: dense_tris + ground_tris,
        instanced_triangles: copies * dense_tris + ground_tris,
        elements: vec!["main".into()],
        cameras: vec!["default".into()],
        nested_instancing: false,
        syntax: Some(Syntax::V4),
    })
}

fn write_scene(
    o: &LodGridOptions,
    ctx: &Ctx<'_>,
    ground: &dyn TriangleSource,
) -> Result<Tally, GenError> {
    let syntax = Syntax::V4;
    let mut out = OutFile::create(ctx.root, "scene.pbrt", ctx.live)?;
    let mut line = Vec::with_capacity(4096);
    let (ex, ez) = extent(o);
    line.extend_from_slice(
        format!(
            "# motu gen lod-grid: grid {} triangles {} spacing {} seed {}\n",
            o.grid, o.triangles, o.spacing, o.seed
        )
        .as_bytes(),
    );
    push_camera(
        &mut line,
        &CameraSpec {
            eye: [0.0, 3.0, -o.spacing * 1.5],
            target: [0.0, 1.0, 0.5 * ez],
            fov_deg: (50.0f64).max((ex / ez).atan().to_degrees()),
        },
    );
    push_film(&mut line, syntax, o.width, o.height, "lod-grid.exr");
    line.extend_from_slice(b"\nWorldBegin\n\n");
    push_sun(&mut line, syntax, [-0.3, 1.0, -0.6], [3.0, 3.0, 3.0]);
    push_material(&mut line, syntax, "dense", [0.6, 0.6, 0.62]);
    push_material(&mut line, syntax, "ground", [0.3, 0.32, 0.3]);
    line.extend_from_slice(
        b"\nObjectBegin \"dense\"\nNamedMaterial \"dense\"\nShape \"plymesh\" \"string filename\" [ \"dense.ply\" ]\nObjectEnd\n\n",
    );
    let (w, h) = (o.grid.width, o.grid.height);
    for j in 0..h {
        for i in 0..w {
            let mut rng = SplitMix64::new(derive_seed(o.seed, &[5, u64::from(j), u64::from(i)]));
            let x = (f64::from(i) - f64::from(w - 1) / 2.0) * o.spacing;
            let z = f64::from(j) * o.spacing + o.spacing;
            let m = Affine::translation([x, 1.15, z])
                .mul(&Affine::rotation(rng.unit_vector(), rng.range(0.0, TAU)));
            push_instance(&mut line, &m, "dense", 4);
            if line.len() > 60_000 {
                out.drain(&mut line)?;
            }
        }
    }
    line.extend_from_slice(b"\nAttributeBegin\nNamedMaterial \"ground\"\n");
    out.drain(&mut line)?;
    write_trianglemesh(&mut out, ground, syntax, 3, &mut line)?;
    out.write_str("AttributeEnd\n")?;
    let bytes = out.finish()?;
    Ok(Tally {
        object_instances: o.grid.count(),
        ..Tally::file(bytes)
    })
}

#[cfg(test)]
mod tests;
