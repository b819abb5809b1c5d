//! `sphereflake`: Haines's classic recursive sphereflake. Every sphere has
//! nine children of a third of its radius (six around its equator, three on
//! its upper hemisphere, oriented outwards). The sphere is one PLY mesh;
//! `depth` N gives N nested instancing levels above the sphere object
//! (`flakeN` holds an instance of `sphere` and nine `flake{N-1}` instances,
//! `flake0` being `sphere`), or one world-level instance per sphere with
//! `flat`.

use std::f64::consts::{PI, TAU};
use std::path::Path;

use crate::math::Affine;
use crate::mesh::{write_ply, write_trianglemesh, ParamGrid, TriangleSource, UvSphere};
use crate::pbrt::{
    push_camera, push_film, push_instance, push_material, push_sun, CameraSpec, Syntax,
};
use crate::rng::{derive_seed, SplitMix64};
use crate::run::{run_jobs, Ctx, Job, Tally};
use crate::text::OutFile;
use crate::{GenError, GenProgress, GenSummary};

/// Options of `motu gen sphereflake`.
#[derive(Clone, Debug, PartialEq)]
pub struct SphereflakeOptions {
    /// Recursion depth: spheres = 1 + 9 + … + 9^depth.
    pub depth: u32,
    /// Segments around the sphere mesh (rings = segments / 2).
    pub sphere_segments: u32,
    /// Seeds the twist of each child about its own axis.
    pub seed: u64,
    pub flat: bool,
    pub width: u32,
    pub height: u32,
}

impl Default for SphereflakeOptions {
    fn default() -> Self {
        Self {
            depth: 3,
            sphere_segments: 32,
            seed: 1,
            flat: false,
            width: 512,
            height: 512,
        }
    }
}

const CHILDREN: usize = 9;
const TRANSLATION_DECIMALS: u32 = 8;

/// parent_from_child for the nine children of a unit sphere.
fn child_transforms(seed: u64) -> Vec<Affine> {
    let mut rng = SplitMix64::new(derive_seed(seed, &[3]));
    (0..CHILDREN)
        .map(|c| {
            let (azimuth, elevation) = if c < 6 {
                (c as f64 * TAU / 6.0, 0.0)
            } else {
                ((c - 6) as f64 * TAU / 3.0 + PI / 6.0, PI / 3.0)
            };
            let dir = [
                elevation.cos() * azimuth.cos(),
                elevation.sin(),
                elevation.cos() * azimuth.sin(),
            ];
            let twist = rng.range(0.0, TAU);
            Affine::translation(crate::math::scale(dir, 1.0 + 1.0 / 3.0))
                .mul(&Affine::rotation_arc([0.0, 1.0, 0.0], dir))
                .mul(&Affine::rotation_y(twist))
                .mul(&Affine::uniform_scale(1.0 / 3.0))
        })
        .collect()
}

fn flake_name(level: u32) -> String {
    if level == 0 {
        "sphere".into()
    } else {
        format!("flake{level}")
    }
}

fn sphere_mesh(segments: u32) -> impl TriangleSource {
    UvSphere::new(segments, segments / 2, |d| d)
}

fn ground_mesh() -> impl TriangleSource {
    ParamGrid::new(2, 2, false, |u, v| {
        [12.0 * (2.0 * u - 1.0), -1.0, 12.0 * (2.0 * v - 1.0)]
    })
}

fn validate(o: &SphereflakeOptions) -> Result<u64, GenError> {
    let invalid = |option, reason: &str| {
        Err(GenError::InvalidOption {
            option,
            reason: reason.into(),
        })
    };
    if o.depth > 20 {
        return invalid("depth", "at most 20");
    }
    if !(3..=4096).contains(&o.sphere_segments) {
        return invalid("sphere-segments", "must be in 3..=4096");
    }
    if o.width == 0 || o.height == 0 {
        return invalid("width", "image width and height must be at least 1");
    }
    let spheres = (0..=o.depth).map(|k| 9u64.pow(k)).sum::<u64>();
    if o.flat && spheres > crate::forest::MAX_FLAT_INSTANCES {
        return Err(GenError::TooLarge(format!(
            "--flat would write {spheres} instance lines; drop --flat or lower --depth"
        )));
    }
    Ok(spheres)
}

pub(crate) fn generate(
    o: &SphereflakeOptions,
    root: &Path,
    progress: &mut dyn FnMut(GenProgress),
) -> Result<GenSummary, GenError> {
    let spheres = validate(o)?;
    let sphere = sphere_mesh(o.sphere_segments);
    let ground = ground_mesh();
    let sphere_tris = u64::from(sphere.triangle_count());
    let ground_tris = u64::from(ground.triangle_count());
    let sphere_ref = &sphere;
    let jobs: Vec<Job<'_>> = vec![
        Box::new(move |ctx: &Ctx<'_>| {
            Ok(Tally::file(write_ply(
                ctx.root,
                "sphere.ply",
                sphere_ref,
                ctx.live,
            )?))
        }),
        Box::new(|ctx: &Ctx<'_>| write_scene(o, ctx, &ground)),
    ];
    let tally = run_jobs(root, jobs, None, progress)?;
    Ok(GenSummary {
        scene_path: root.join("scene.pbrt"),
        files_written: tally.files,
        bytes_written: tally.bytes,
        object_instances: tally.object_instances,
        flattened_instances: spheres,
        unique_triangles: sphere_tris + ground_tris,
        instanced_triangles: spheres * sphere_tris + ground_tris,
        elements: vec!["main".into()],
        cameras: vec!["default".into()],
        nested_instancing: !o.flat && o.depth > 0,
        syntax: Some(Syntax::V4),
    })
}

fn write_scene(
    o: &SphereflakeOptions,
    ctx: &Ctx<'_>,
    ground: &dyn TriangleSource,
) -> Result<Tally, GenError> {
    let syntax = Syntax::V4;
    let mut out = OutFile::create(ctx.root, "scene.pbrt", ctx.live)?;
    let mut line = Vec::with_capacity(4096);
    line.extend_from_slice(
        format!(
            "# motu gen sphereflake: depth {} seed {}{}\n",
            o.depth,
            o.seed,
            if o.flat { " flat" } else { "" }
        )
        .as_bytes(),
    );
    if !o.flat {
        line.extend_from_slice(
            b"# Uses motu's nested-instancing extension (ObjectInstance inside ObjectBegin); pbrt rejects it.\n",
        );
    }
    push_camera(
        &mut line,
        &CameraSpec {
            eye: [2.6, 2.1, 3.4],
            target: [0.0, 0.2, 0.0],
            fov_deg: 45.0,
        },
    );
    push_film(&mut line, syntax, o.width, o.height, "sphereflake.exr");
    line.extend_from_slice(b"\nWorldBegin\n\n");
    push_sun(&mut line, syntax, [0.5, 1.0, 0.7], [3.0, 3.0, 3.0]);
    push_material(&mut line, syntax, "flake", [0.7, 0.55, 0.35]);
    push_material(&mut line, syntax, "ground", [0.4, 0.4, 0.42]);
    let children = child_transforms(o.seed);
    let mut instances = 0u64;
    if o.flat {
        line.extend_from_slice(
            b"\nObjectBegin \"sphere\"\nNamedMaterial \"flake\"\nShape \"plymesh\" \"string filename\" [ \"sphere.ply\" ]\nObjectEnd\n\n",
        );
        // Depth-first walk; the stack holds at most 9·depth transforms.
        let mut stack = vec![(Affine::IDENTITY, 0u32)];
        while let Some((world_from_sphere, level)) = stack.pop() {
            push_instance(
                &mut line,
                &world_from_sphere,
                "sphere",
                TRANSLATION_DECIMALS,
            );
            instances += 1;
            if line.len() > 60_000 {
                out.drain(&mut line)?;
            }
            if level < o.depth {
                for c in children.iter().rev() {
                    stack.push((world_from_sphere.mul(c), level + 1));
                }
            }
        }
    } else {
        // The sphere is defined once; `flakeK` = the sphere + nine `flake{K-1}`.
        line.extend_from_slice(
            b"\nObjectBegin \"sphere\"\nNamedMaterial \"flake\"\nShape \"plymesh\" \"string filename\" [ \"sphere.ply\" ]\nObjectEnd\n",
        );
        for level in 1..=o.depth {
            line.extend_from_slice(format!("\nObjectBegin \"{}\"\n", flake_name(level)).as_bytes());
            push_instance(&mut line, &Affine::IDENTITY, "sphere", TRANSLATION_DECIMALS);
            let child = flake_name(level - 1);
            for c in &children {
                push_instance(&mut line, c, &child, TRANSLATION_DECIMALS);
            }
            instances += 1 + CHILDREN as u64;
            line.extend_from_slice(b"ObjectEnd\n");
        }
        line.extend_from_slice(b"\n");
        push_instance(
            &mut line,
            &Affine::IDENTITY,
            &flake_name(o.depth),
            TRANSLATION_DECIMALS,
        );
        instances += 1;
    }
    line.extend_from_slice(b"\nAttributeBegin\nNamedMaterial \"ground\"\n");
    out.drain(&mut line)?;
    write_trianglemesh(&mut out, ground, syntax, 3, &mut line)?;
    out.write_str("AttributeEnd\n")?;
    let bytes = out.finish()?;
    Ok(Tally {
        object_instances: instances,
        ..Tally::file(bytes)
    })
}

#[cfg(test)]
mod tests;
