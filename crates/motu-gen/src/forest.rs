//! `forest`: a tree (trunk PLY + instanced leaves) instanced on grids of
//! grids. `levels` grid levels sit above the tree; the thesis's (3·4)^3
//! layout is `levels = 3, grid = 4x3` (world → 12 groups → 12 groups → 12
//! trees → 8,732 leaves in the thesis; `leaves` here).

use std::f64::consts::{PI, TAU};
use std::path::Path;

use crate::math::{normalize, Affine};
use crate::mesh::{write_ply, write_trianglemesh, Mesh, ParamGrid, TriangleSource};
use crate::pbrt::{
    push_camera, push_film, push_instance, push_material, push_sun, CameraSpec, Syntax,
};
use crate::rng::{derive_seed, SplitMix64};
use crate::run::{run_jobs, Ctx, Job, Tally};
use crate::text::OutFile;
use crate::{GenError, GenProgress, GenSummary, GridSize};

/// Options of `motu gen forest`.
#[derive(Clone, Debug, PartialEq)]
pub struct ForestOptions {
    /// Grid instancing levels above the tree (≥ 1); trees = (W·H)^levels.
    pub levels: u32,
    /// Copies per level: a W×H grid of the level below.
    pub grid: GridSize,
    /// Leaf instances per tree.
    pub leaves: u32,
    /// Segments around the trunk (its triangle count grows with the square).
    pub trunk_segments: u32,
    pub seed: u64,
    /// Standard single-level pbrt: every trunk and leaf at world level.
    pub flat: bool,
    pub width: u32,
    pub height: u32,
}

impl Default for ForestOptions {
    fn default() -> Self {
        Self {
            levels: 2,
            grid: GridSize::new(4, 3),
            leaves: 1000,
            trunk_segments: 16,
            seed: 1,
            flat: false,
            width: 640,
            height: 360,
        }
    }
}

/// Most instance lines a `flat` scene may have (~200 bytes each).
pub(crate) const MAX_FLAT_INSTANCES: u64 = 1 << 30;
const TREE_SPACING: f64 = 9.0;
const TRANSLATION_DECIMALS: u32 = 4;
const LEAF_STREAM: u64 = 1;
const GRID_STREAM: u64 = 2;

fn trunk_mesh(segments: u32) -> Mesh {
    let segments = segments.max(3);
    let rows = segments.max(4);
    let cylinder = |r0: f64, r1: f64, length: f64| {
        ParamGrid::new(segments, rows, true, move |u, v| {
            let r = r0 + (r1 - r0) * v;
            let a = u * TAU;
            [r * a.cos(), v * length, r * a.sin()]
        })
    };
    let mut mesh = Mesh::default();
    mesh.append(&cylinder(0.4, 0.12, 8.0), &Affine::IDENTITY);
    // Five branches, fixed so every seed shares the tree's silhouette.
    for b in 0..5u32 {
        let height = 3.5 + 0.7 * f64::from(b);
        let yaw = f64::from(b) * 2.4;
        let dir = normalize([yaw.cos(), 0.8, yaw.sin()]);
        let m = Affine::translation([0.0, height, 0.0])
            .mul(&Affine::rotation_arc([0.0, 1.0, 0.0], dir));
        mesh.append(&cylinder(0.14, 0.04, 2.8), &m);
    }
    mesh
}

/// A slightly folded, curled leaf, 0.35 long, 8 triangles.
fn leaf_mesh() -> impl TriangleSource {
    ParamGrid::new(3, 3, false, |u, v| {
        let s = 2.0 * u - 1.0;
        let half_width = 0.1 * (0.15 + (PI * v).sin());
        [s * half_width, v * 0.35, 0.03 * s.abs() + 0.05 * v * v]
    })
}

/// tree_from_leaf for leaf `index`: a random point of the crown, random
/// orientation and size.
fn leaf_transform(seed: u64, index: u64) -> Affine {
    let mut rng = SplitMix64::new(derive_seed(seed, &[LEAF_STREAM, index]));
    let dir = rng.unit_vector();
    let r = rng.next_f64().cbrt();
    let pos = [3.0 * r * dir[0], 7.5 + 2.2 * r * dir[1], 3.0 * r * dir[2]];
    let rotation = Affine::rotation(rng.unit_vector(), rng.range(0.0, TAU));
    Affine::translation(pos)
        .mul(&rotation)
        .mul(&Affine::uniform_scale(rng.range(0.8, 1.2)))
}

/// Placements of one grid level: `level` 1 places trees, higher levels groups.
fn level_placements(o: &ForestOptions, level: u32) -> Vec<Affine> {
    let (w, h) = (o.grid.width, o.grid.height);
    let spacing_x = TREE_SPACING * f64::from(w).powi(level as i32 - 1);
    let spacing_z = TREE_SPACING * f64::from(h).powi(level as i32 - 1);
    let mut out = Vec::with_capacity(o.grid.count() as usize);
    for j in 0..h {
        for i in 0..w {
            let mut rng = SplitMix64::new(derive_seed(
                o.seed,
                &[GRID_STREAM, u64::from(level), u64::from(j * w + i)],
            ));
            let x = (f64::from(i) - f64::from(w - 1) / 2.0) * spacing_x;
            let z = (f64::from(j) - f64::from(h - 1) / 2.0) * spacing_z;
            let m = if level == 1 {
                let jitter = 0.25 * TREE_SPACING;
                Affine::translation([
                    x + rng.range(-jitter, jitter),
                    0.0,
                    z + rng.range(-jitter, jitter),
                ])
                .mul(&Affine::rotation_y(rng.range(0.0, TAU)))
                .mul(&Affine::uniform_scale(rng.range(0.85, 1.15)))
            } else {
                // Half turns keep a group's rectangular footprint.
                let turn = if rng.below(2) == 0 { 0.0 } else { PI };
                Affine::translation([x, 0.0, z]).mul(&Affine::rotation_y(turn))
            };
            out.push(m);
        }
    }
    out
}

fn object_name(level: u32) -> String {
    if level == 0 {
        "tree".to_string()
    } else {
        format!("group{level}")
    }
}

fn validate(o: &ForestOptions) -> Result<u64, GenError> {
    let invalid = |option, reason: &str| {
        Err(GenError::InvalidOption {
            option,
            reason: reason.into(),
        })
    };
    if o.levels == 0 {
        return invalid("levels", "must be at least 1");
    }
    if !(3..=512).contains(&o.trunk_segments) {
        return invalid("trunk-segments", "must be in 3..=512");
    }
    if o.leaves > 10_000_000 {
        return invalid("leaves", "at most 10,000,000 per tree");
    }
    if o.width == 0 || o.height == 0 {
        return invalid("width", "image width and height must be at least 1");
    }
    let trees = o.grid.count().checked_pow(o.levels).ok_or_else(|| {
        GenError::TooLarge(format!("({})^{} trees overflow", o.grid.count(), o.levels))
    })?;
    let flattened = trees.checked_mul(1 + u64::from(o.leaves));
    match flattened {
        Some(n) if !o.flat || n <= MAX_FLAT_INSTANCES => Ok(trees),
        Some(n) => Err(GenError::TooLarge(format!(
            "--flat would write {n} instance lines (limit {MAX_FLAT_INSTANCES}); drop --flat to use nested instancing"
        ))),
        None => Err(GenError::TooLarge("flattened instance count overflows u64".into())),
    }
}

pub(crate) fn generate(
    o: &ForestOptions,
    root: &Path,
    progress: &mut dyn FnMut(GenProgress),
) -> Result<GenSummary, GenError> {
    let trees = validate(o)?;
    let trunk = trunk_mesh(o.trunk_segments);
    let leaf = leaf_mesh();
    let trunk_tris = u64::from(trunk.triangle_count());
    let leaf_tris = u64::from(leaf.triangle_count());
    let leaves = u64::from(o.leaves);
    let ground = ground_mesh(o);

    let trunk_ref = &trunk;
    let jobs: Vec<Job<'_>> = vec![
        Box::new(move |ctx: &Ctx<'_>| {
            Ok(Tally::file(write_ply(
                ctx.root,
                "trunk.ply",
                trunk_ref,
                ctx.live,
            )?))
        }),
        Box::new(|ctx: &Ctx<'_>| write_scene(o, ctx, &leaf, &ground, trees)),
    ];
    let mut tally = run_jobs(root, jobs, None, progress)?;
    tally.unique_triangles = trunk_tris + leaf_tris + u64::from(ground.triangle_count());
    tally.flattened_instances = trees * (1 + leaves);
    tally.instanced_triangles =
        trees * (trunk_tris + leaves * leaf_tris) + u64::from(ground.triangle_count());
    Ok(GenSummary {
        scene_path: root.join("scene.pbrt"),
        files_written: tally.files,
        bytes_written: tally.bytes,
        object_instances: tally.object_instances,
        flattened_instances: tally.flattened_instances,
        unique_triangles: tally.unique_triangles,
        instanced_triangles: tally.instanced_triangles,
        elements: vec!["main".into()],
        cameras: vec!["default".into()],
        nested_instancing: !o.flat,
        syntax: Some(Syntax::V4),
    })
}

fn extent(o: &ForestOptions) -> (f64, f64) {
    (
        TREE_SPACING * f64::from(o.grid.width).powi(o.levels as i32),
        TREE_SPACING * f64::from(o.grid.height).powi(o.levels as i32),
    )
}

fn ground_mesh(o: &ForestOptions) -> impl TriangleSource {
    let (x, z) = extent(o);
    let (hx, hz) = (0.6 * x + 10.0, 0.6 * z + 10.0);
    ParamGrid::new(2, 2, false, move |u, v| {
        [hx * (2.0 * u - 1.0), 0.0, hz * (2.0 * v - 1.0)]
    })
}

fn write_scene(
    o: &ForestOptions,
    ctx: &Ctx<'_>,
    leaf: &dyn TriangleSource,
    ground: &dyn TriangleSource,
    trees: u64,
) -> Result<Tally, GenError> {
    let syntax = Syntax::V4;
    let mut out = OutFile::create(ctx.root, "scene.pbrt", ctx.live)?;
    let mut line = Vec::with_capacity(4096);
    let mut instances = 0u64;
    let (ex, ez) = extent(o);
    let size = ex.max(ez);
    line.extend_from_slice(
        format!(
            "# motu gen forest: levels {} grid {} leaves {} seed {}{}\n",
            o.levels,
            o.grid,
            o.leaves,
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
            eye: [0.45 * ex + 12.0, 0.22 * size + 14.0, -0.55 * ez - 12.0],
            target: [0.0, 4.0, 0.0],
            fov_deg: 50.0,
        },
    );
    push_film(&mut line, syntax, o.width, o.height, "forest.exr");
    line.extend_from_slice(b"\nWorldBegin\n\n");
    push_sun(&mut line, syntax, [0.4, 1.0, -0.3], [3.0, 2.9, 2.7]);
    push_material(&mut line, syntax, "bark", [0.25, 0.17, 0.1]);
    push_material(&mut line, syntax, "leaf", [0.12, 0.4, 0.08]);
    push_material(&mut line, syntax, "ground", [0.35, 0.3, 0.22]);
    line.extend_from_slice(b"\nObjectBegin \"leaf\"\nNamedMaterial \"leaf\"\n");
    out.drain(&mut line)?;
    write_trianglemesh(&mut out, leaf, syntax, 5, &mut line)?;
    line.extend_from_slice(b"ObjectEnd\n\n");

    if o.flat {
        line.extend_from_slice(
            b"ObjectBegin \"trunk\"\nNamedMaterial \"bark\"\nShape \"plymesh\" \"string filename\" [ \"trunk.ply\" ]\nObjectEnd\n\n",
        );
        out.drain(&mut line)?;
        let placements: Vec<Vec<Affine>> = (1..=o.levels)
            .map(|level| level_placements(o, level))
            .collect();
        let per_level = o.grid.count();
        for tree in 0..trees {
            // Digits of `tree` in base W·H pick one placement per level.
            let mut world_from_tree = Affine::IDENTITY;
            let mut rest = tree;
            for level in (0..o.levels as usize).rev() {
                let digit = (rest % per_level) as usize;
                rest /= per_level;
                world_from_tree = world_from_tree.mul(&placements[level][digit]);
            }
            push_instance(&mut line, &world_from_tree, "trunk", TRANSLATION_DECIMALS);
            for l in 0..u64::from(o.leaves) {
                push_instance(
                    &mut line,
                    &world_from_tree.mul(&leaf_transform(o.seed, l)),
                    "leaf",
                    TRANSLATION_DECIMALS,
                );
                if line.len() > 60_000 {
                    out.drain(&mut line)?;
                }
            }
            instances += 1 + u64::from(o.leaves);
            out.drain(&mut line)?;
        }
    } else {
        line.extend_from_slice(
            b"ObjectBegin \"tree\"\nAttributeBegin\nNamedMaterial \"bark\"\nShape \"plymesh\" \"string filename\" [ \"trunk.ply\" ]\nAttributeEnd\n",
        );
        for l in 0..u64::from(o.leaves) {
            push_instance(
                &mut line,
                &leaf_transform(o.seed, l),
                "leaf",
                TRANSLATION_DECIMALS,
            );
            if line.len() > 60_000 {
                out.drain(&mut line)?;
            }
        }
        line.extend_from_slice(b"ObjectEnd\n\n");
        instances += u64::from(o.leaves);
        for level in 1..o.levels {
            line.extend_from_slice(format!("ObjectBegin \"{}\"\n", object_name(level)).as_bytes());
            for m in level_placements(o, level) {
                push_instance(&mut line, &m, &object_name(level - 1), TRANSLATION_DECIMALS);
            }
            line.extend_from_slice(b"ObjectEnd\n\n");
            instances += o.grid.count();
        }
        for m in level_placements(o, o.levels) {
            push_instance(
                &mut line,
                &m,
                &object_name(o.levels - 1),
                TRANSLATION_DECIMALS,
            );
        }
        instances += o.grid.count();
        out.drain(&mut line)?;
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
