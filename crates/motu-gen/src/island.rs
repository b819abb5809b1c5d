//! `island`: a Moana-like scene in standard pbrt-v3 (no extensions), the
//! stress test for importers at production scale.
//!
//! Layout (paths relative to `DIR`, the way Moana's `island.pbrt` refers to them):
//!
//! ```text
//! scene.pbrt                        Film, cameras/*.pbrt (shotCam last = active), WorldBegin,
//!                                   materials, one Include per element, WorldEnd
//! cameras/<cam>.pbrt                Identity + LookAt + Camera "perspective"
//! <elem>/<elem>.pbrt                the element: its archives, base geometry, placements
//! <elem>/archives/<elem>_<kind>_<v>.pbrt   ObjectBegin "<elem>_<kind>_<v>" … ObjectEnd
//! <elem>/<elem>_geometry_NNNN.pbrt  inline `trianglemesh` terrain patches (huge arrays at scale)
//! <elem>/geometry/<elem>_geometry_NNNNN.ply   binary PLY patches / trunk sections (`plymesh`)
//! <elem>/<elem>_<xgList>[_NNNN].pbrt   one `AttributeBegin Transform [16] ObjectInstance "…" AttributeEnd` per line
//! ```
//!
//! Counts scale linearly with `scale` (1 ≈ Moana: ~28M instances, ~36 GB);
//! plants are flattened the way Moana v3 is (every leaf of every copy is a
//! world-level instance with a composed transform). Work is split into
//! per-file jobs, each with its own seed, written in parallel with bounded
//! memory (a 1 MiB buffer per thread; no mesh or list is ever materialised
//! except archives of at most a few thousand triangles).
//!
//! Measured (release build, 2 shared cores, ext4, `examples/gen.rs` under
//! `/usr/bin/time -v`): `--scale 0.14` wrote 5.68 GB in 309 files with
//! 3.88M instances in 18.9 s (301 MB/s), peak RSS 6.7 MB. `--scale 1`
//! extrapolates to ~28M instances and ~37 GB. `cargo bench -p motu-gen`
//! measures throughput at scale 0.002 (~320 MiB/s on the same machine).

use std::f64::consts::{PI, TAU};
use std::ops::Range;
use std::path::Path;

use crate::math::{normalize, Affine, Vec3};
use crate::mesh::{
    write_ply, write_trianglemesh, Mesh, ParamGrid, SineNoise, TriangleSource, UvSphere,
    ValueNoise2,
};
use crate::pbrt::{
    push_camera, push_film, push_instance, push_material, push_sun, CameraSpec, Syntax,
};
use crate::rng::{derive_seed, SplitMix64};
use crate::run::{run_jobs, Ctx, Job, Tally};
use crate::text::OutFile;
use crate::{GenError, GenProgress, GenSummary};

mod archives;
mod catalog;
mod moana_json;
mod plan;
mod terrain;
mod writers;

use archives::*;
use catalog::*;
use plan::*;
use terrain::*;
use writers::*;

/// Options of `motu gen island`.
#[derive(Clone, Debug, PartialEq)]
pub struct IslandOptions {
    /// 1.0 ≈ Moana (about 28M instances and 36 GB); counts scale linearly.
    pub scale: f64,
    pub seed: u64,
    /// Number of elements (1..=20, Moana's names in priority order); `None`
    /// picks 5 below scale 0.002, 8 below 0.01, 12 below 0.05, 16 below 0.2, else 20.
    pub elements: Option<u32>,
    /// Instance lines per placement file before it is split.
    pub max_instances_per_file: u64,
    /// Triangles per mesh (terrain patch, trunk section) before it is split.
    pub max_mesh_triangles: u32,
    /// Wrap each terrain geometry file (an inline group of patches or one PLY patch) in an
    /// object of its own, instanced once where it lies: importers then give every patch its
    /// own BLAS, the unit that out-of-core streaming builds and evicts. Off by default: Moana
    /// puts terrain at world level, which importers merge into a few huge BLASes.
    pub terrain_objects: bool,
    /// Writer threads (`None`: rayon's default, one per core).
    pub threads: Option<usize>,
    pub width: u32,
    pub height: u32,
    /// pbrt-v3 (Moana's pbrt release) or the layout of Moana's JSON+OBJ base package.
    pub format: IslandFormat,
}

/// The file layout `motu gen island` writes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum IslandFormat {
    /// `scene.pbrt` and its includes (pbrt-v3, PLY).
    #[default]
    Pbrt,
    /// `json/island.json`, element JSON, archive JSON and OBJ files.
    MoanaJson,
}

impl Default for IslandOptions {
    fn default() -> Self {
        Self {
            scale: 0.0005,
            seed: 1,
            elements: None,
            max_instances_per_file: 500_000,
            max_mesh_triangles: 1_000_000,
            terrain_objects: false,
            threads: None,
            width: 1024,
            height: 429,
            format: IslandFormat::Pbrt,
        }
    }
}

/// Moana's seven cameras; `shotCam` is included last, so it is the active one.
pub const ISLAND_CAMERAS: [&str; 7] = [
    "beachCam",
    "birdseyeCam",
    "dunesACam",
    "grassCam",
    "palmsCam",
    "rootsCam",
    "shotCam",
];

/// Moana's twenty elements, in the order they are added as `elements` grows.
pub const ISLAND_ELEMENTS: [&str; 20] = [
    "isBeach",
    "isMountainA",
    "isPalmRig",
    "isCoral",
    "osOcean",
    "isIronwoodA1",
    "isDunesA",
    "isHibiscus",
    "isLavaRocks",
    "isBayCedarA1",
    "isMountainB",
    "isCoastline",
    "isDunesB",
    "isGardeniaA",
    "isHibiscusYoung",
    "isIronwoodB",
    "isKava",
    "isNaupakaA",
    "isPalmDead",
    "isPandanusA",
];

const INSTANCES_AT_SCALE_1: f64 = 28.0e6;
const INLINE_TRIANGLES_AT_SCALE_1: f64 = 700.0e6;
const PLY_TRIANGLES_AT_SCALE_1: f64 = 480.0e6;
/// The sun: where it shines from, and its radiance.
const SUN_FROM: Vec3 = [0.35, 1.0, 0.55];
const SUN_RADIANCE: Vec3 = [3.0, 2.9, 2.7];
/// Island radius in scene units; the ocean reaches 3 radii.
const RADIUS: f64 = 2000.0;
const POSITION_DECIMALS: u32 = 3;

// ---------------------------------------------------------------- placements

fn validate(o: &IslandOptions) -> Result<(), GenError> {
    let invalid = |option, reason: String| Err(GenError::InvalidOption { option, reason });
    if !(o.scale.is_finite() && o.scale > 0.0 && o.scale <= 8.0) {
        return invalid("scale", format!("{} is not in (0, 8]", o.scale));
    }
    if let Some(n) = o.elements {
        if !(1..=20).contains(&n) {
            return invalid("elements", format!("{n} is not in 1..=20"));
        }
    }
    if o.max_instances_per_file == 0 {
        return invalid("max-instances-per-file", "must be at least 1".into());
    }
    if !(64..=1 << 30).contains(&o.max_mesh_triangles) {
        return invalid("max-mesh-triangles", "must be in 64..=2^30".into());
    }
    if o.width == 0 || o.height == 0 {
        return invalid("width", "image width and height must be at least 1".into());
    }
    Ok(())
}

pub(crate) fn generate(
    o: &IslandOptions,
    root: &Path,
    progress: &mut dyn FnMut(GenProgress),
) -> Result<GenSummary, GenError> {
    validate(o)?;
    if o.format == IslandFormat::MoanaJson {
        return moana_json::generate(o, root, progress);
    }
    let terrain = Terrain::new(o.seed);
    let elements = plan(o);
    let cams = cameras(&terrain);
    let (t, els, cam_ref) = (&terrain, &elements, &cams);
    let mut jobs: Vec<Job<'_>> = Vec::new();
    // Biggest jobs first so the last ones to finish are short.
    for e in els {
        for (li, list) in e.lists.iter().enumerate() {
            for (file, range) in &list.files {
                jobs.push(Box::new(move |ctx: &Ctx<'_>| {
                    write_placements(o, ctx, t, e, li, file, range.clone())
                }));
            }
        }
        for (file, patches) in &e.inline_files {
            jobs.push(Box::new(move |ctx: &Ctx<'_>| {
                write_inline_file(ctx, t, file, patches)
            }));
        }
        for (file, patch) in &e.ply_patches {
            jobs.push(Box::new(move |ctx: &Ctx<'_>| {
                let bytes = write_ply(ctx.root, file, &patch.source(t), ctx.live)?;
                let tris = patch.triangles();
                Ok(Tally {
                    unique_triangles: tris,
                    instanced_triangles: tris,
                    ..Tally::file(bytes)
                })
            }));
        }
        for (archive, section, file) in &e.trunk_sections {
            jobs.push(Box::new(move |ctx: &Ctx<'_>| {
                let ArchiveBody::Trunk { spec, .. } = &e.archives[*archive].body else {
                    return Err(GenError::Worker("trunk section without a trunk".into()));
                };
                let source = spec.section(*section);
                let bytes = write_ply(ctx.root, file, &source, ctx.live)?;
                // Instanced triangles are counted per placement line.
                Ok(Tally {
                    unique_triangles: u64::from(source.triangle_count()),
                    ..Tally::file(bytes)
                })
            }));
        }
        for a in &e.archives {
            jobs.push(Box::new(move |ctx: &Ctx<'_>| write_archive_file(ctx, a)));
        }
        jobs.push(Box::new(move |ctx: &Ctx<'_>| write_element_file(o, ctx, e)));
    }
    for (name, spec) in cam_ref {
        jobs.push(Box::new(move |ctx: &Ctx<'_>| {
            write_camera_file(ctx, name, spec)
        }));
    }
    jobs.push(Box::new(move |ctx: &Ctx<'_>| write_scene_file(o, ctx, els)));
    tracing::debug!(jobs = jobs.len(), elements = els.len(), "island plan");
    let tally = run_jobs(root, jobs, o.threads, progress)?;
    Ok(GenSummary {
        scene_path: root.join("scene.pbrt"),
        files_written: tally.files,
        bytes_written: tally.bytes,
        object_instances: tally.object_instances,
        flattened_instances: tally.flattened_instances,
        unique_triangles: tally.unique_triangles,
        instanced_triangles: tally.instanced_triangles,
        elements: elements.iter().map(|e| e.name.to_string()).collect(),
        cameras: ISLAND_CAMERAS.iter().map(|c| c.to_string()).collect(),
        nested_instancing: false,
        syntax: Some(Syntax::V3),
    })
}

#[cfg(test)]
mod tests;
