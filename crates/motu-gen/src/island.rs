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
mod moana_json;
mod terrain;
mod writers;

use archives::*;
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

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum ArchiveKind {
    Rock,
    Shell,
    Grass,
    Flower,
    Coral,
    Leaf,
    Frond,
}

impl ArchiveKind {
    fn name(self) -> &'static str {
        match self {
            ArchiveKind::Rock => "rock",
            ArchiveKind::Shell => "shell",
            ArchiveKind::Grass => "grass",
            ArchiveKind::Flower => "flower",
            ArchiveKind::Coral => "coral",
            ArchiveKind::Leaf => "leaf",
            ArchiveKind::Frond => "frond",
        }
    }

    fn list_name(self) -> &'static str {
        match self {
            ArchiveKind::Rock => "xgRocks",
            ArchiveKind::Shell => "xgShells",
            ArchiveKind::Grass => "xgGrass",
            ArchiveKind::Flower => "xgFlowers",
            ArchiveKind::Coral => "xgCoral",
            ArchiveKind::Leaf | ArchiveKind::Frond => "xgLeaves",
        }
    }

    fn material(self) -> &'static str {
        match self {
            ArchiveKind::Rock => "rock",
            ArchiveKind::Shell => "shell",
            ArchiveKind::Grass => "grass",
            ArchiveKind::Flower => "flower",
            ArchiveKind::Coral => "coral",
            ArchiveKind::Leaf | ArchiveKind::Frond => "leaf",
        }
    }

    /// Uniform scale range of placed copies (archives are ~1 unit tall).
    fn scale_range(self) -> (f64, f64) {
        match self {
            ArchiveKind::Rock => (0.6, 5.0),
            ArchiveKind::Shell => (0.15, 0.5),
            ArchiveKind::Grass => (0.5, 1.4),
            ArchiveKind::Flower => (0.4, 1.0),
            ArchiveKind::Coral => (0.8, 3.0),
            ArchiveKind::Leaf | ArchiveKind::Frond => (1.0, 1.0),
        }
    }
}

#[derive(Clone, Copy, Debug)]
enum Role {
    /// Land tiles with scattered archives: (kind, share of the element's instances).
    Terrain(&'static str, &'static [(ArchiveKind, f64)]),
    Coral,
    Ocean,
    /// A plant species: height in units, palm-like fronds or a leafy crown.
    Plant {
        height: f64,
        palm: bool,
    },
}

struct ElementDef {
    name: &'static str,
    role: Role,
    instance_weight: f64,
    inline_weight: f64,
    ply_weight: f64,
}

const fn def(
    name: &'static str,
    role: Role,
    instance_weight: f64,
    inline_weight: f64,
    ply_weight: f64,
) -> ElementDef {
    ElementDef {
        name,
        role,
        instance_weight,
        inline_weight,
        ply_weight,
    }
}

const PLANT_SMALL: f64 = 0.01;
static DEFS: [ElementDef; 20] = [
    def(
        "isBeach",
        Role::Terrain(
            "sand",
            &[
                (ArchiveKind::Shell, 0.4),
                (ArchiveKind::Rock, 0.3),
                (ArchiveKind::Grass, 0.3),
            ],
        ),
        0.10,
        0.18,
        0.06,
    ),
    def(
        "isMountainA",
        Role::Terrain(
            "mountain",
            &[
                (ArchiveKind::Grass, 0.5),
                (ArchiveKind::Rock, 0.2),
                (ArchiveKind::Flower, 0.3),
            ],
        ),
        0.05,
        0.16,
        0.06,
    ),
    def(
        "isPalmRig",
        Role::Plant {
            height: 14.0,
            palm: true,
        },
        0.06,
        PLANT_SMALL,
        0.06,
    ),
    def("isCoral", Role::Coral, 0.10, 0.04, 0.08),
    def("osOcean", Role::Ocean, 0.0, 0.10, 0.12),
    def(
        "isIronwoodA1",
        Role::Plant {
            height: 20.0,
            palm: false,
        },
        0.12,
        PLANT_SMALL,
        0.07,
    ),
    def(
        "isDunesA",
        Role::Terrain(
            "sand",
            &[(ArchiveKind::Grass, 0.7), (ArchiveKind::Flower, 0.3)],
        ),
        0.04,
        0.10,
        0.04,
    ),
    def(
        "isHibiscus",
        Role::Plant {
            height: 4.0,
            palm: false,
        },
        0.04,
        PLANT_SMALL,
        0.04,
    ),
    def(
        "isLavaRocks",
        Role::Terrain("lava", &[(ArchiveKind::Rock, 1.0)]),
        0.03,
        0.08,
        0.04,
    ),
    def(
        "isBayCedarA1",
        Role::Plant {
            height: 10.0,
            palm: false,
        },
        0.08,
        PLANT_SMALL,
        0.08,
    ),
    def(
        "isMountainB",
        Role::Terrain(
            "mountain",
            &[
                (ArchiveKind::Grass, 0.5),
                (ArchiveKind::Rock, 0.3),
                (ArchiveKind::Flower, 0.2),
            ],
        ),
        0.05,
        0.14,
        0.05,
    ),
    def(
        "isCoastline",
        Role::Terrain(
            "sand",
            &[(ArchiveKind::Rock, 0.6), (ArchiveKind::Shell, 0.4)],
        ),
        0.03,
        0.10,
        0.04,
    ),
    def(
        "isDunesB",
        Role::Terrain(
            "sand",
            &[(ArchiveKind::Grass, 0.8), (ArchiveKind::Shell, 0.2)],
        ),
        0.06,
        0.10,
        0.04,
    ),
    def(
        "isGardeniaA",
        Role::Plant {
            height: 3.0,
            palm: false,
        },
        0.04,
        PLANT_SMALL,
        0.03,
    ),
    def(
        "isHibiscusYoung",
        Role::Plant {
            height: 2.0,
            palm: false,
        },
        0.02,
        PLANT_SMALL,
        0.02,
    ),
    def(
        "isIronwoodB",
        Role::Plant {
            height: 16.0,
            palm: false,
        },
        0.05,
        PLANT_SMALL,
        0.04,
    ),
    def(
        "isKava",
        Role::Plant {
            height: 2.5,
            palm: false,
        },
        0.03,
        PLANT_SMALL,
        0.02,
    ),
    def(
        "isNaupakaA",
        Role::Plant {
            height: 2.0,
            palm: false,
        },
        0.04,
        PLANT_SMALL,
        0.02,
    ),
    def(
        "isPalmDead",
        Role::Plant {
            height: 12.0,
            palm: true,
        },
        0.02,
        PLANT_SMALL,
        0.02,
    ),
    def(
        "isPandanusA",
        Role::Plant {
            height: 7.0,
            palm: true,
        },
        0.04,
        PLANT_SMALL,
        0.03,
    ),
];

/// Materials defined in `scene.pbrt` (pbrt-v3 `matte`).
const MATERIALS: [(&str, Vec3); 11] = [
    ("sand", [0.76, 0.68, 0.5]),
    ("mountain", [0.32, 0.36, 0.22]),
    ("lava", [0.15, 0.13, 0.12]),
    ("water", [0.05, 0.2, 0.3]),
    ("rock", [0.4, 0.38, 0.35]),
    ("shell", [0.85, 0.8, 0.75]),
    ("grass", [0.3, 0.5, 0.15]),
    ("flower", [0.85, 0.2, 0.25]),
    ("coral", [0.9, 0.45, 0.4]),
    ("leaf", [0.12, 0.38, 0.08]),
    ("bark", [0.3, 0.22, 0.15]),
];

// ---------------------------------------------------------------- placements

#[derive(Clone, Debug)]
enum ListKind {
    /// Archives `archives` scattered over `region`.
    Scatter {
        region: Vec<Rect>,
        archives: Range<usize>,
        kind: ArchiveKind,
    },
    /// One trunk archive per plant copy.
    PlantCopies { trunk: usize },
    /// `leaves_per_plant` leaves of every copy, composed with the copy's transform.
    PlantLeaves {
        leaves_per_plant: u64,
        archives: Range<usize>,
    },
}

struct PlacementList {
    kind: ListKind,
    /// Per file: its path and the instance indices it holds.
    files: Vec<(String, Range<u64>)>,
}

struct ElementPlan {
    index: u64,
    name: &'static str,
    material: &'static str,
    archives: Vec<Archive>,
    inline_files: Vec<(String, Vec<Patch>)>,
    ply_patches: Vec<(String, Patch)>,
    /// (trunk archive index, section index, file)
    trunk_sections: Vec<(usize, u32, String)>,
    lists: Vec<PlacementList>,
    plant: Option<(f64, bool, u64)>, // (height, palm, copies)
}

fn element_count(o: &IslandOptions) -> u32 {
    o.elements.unwrap_or(if o.scale < 0.002 {
        5
    } else if o.scale < 0.01 {
        8
    } else if o.scale < 0.05 {
        12
    } else if o.scale < 0.2 {
        16
    } else {
        20
    })
}

fn split_files(prefix: &str, count: u64, max_per_file: u64) -> Vec<(String, Range<u64>)> {
    let files = count.div_ceil(max_per_file).max(1);
    (0..files)
        .map(|f| {
            let start = f * max_per_file;
            let end = (start + max_per_file).min(count);
            let name = if files == 1 {
                format!("{prefix}.pbrt")
            } else {
                format!("{prefix}_{f:04}.pbrt")
            };
            (name, start..end)
        })
        .collect()
}

fn plan(o: &IslandOptions) -> Vec<ElementPlan> {
    let count = element_count(o) as usize;
    let active: Vec<&str> = ISLAND_ELEMENTS[..count].to_vec();
    let defs: Vec<&ElementDef> = DEFS.iter().filter(|d| active.contains(&d.name)).collect();
    let sum = |f: fn(&ElementDef) -> f64| defs.iter().map(|d| f(d)).sum::<f64>().max(1e-9);
    let (w_inst, w_inline, w_ply) = (
        sum(|d| d.instance_weight),
        sum(|d| d.inline_weight),
        sum(|d| d.ply_weight),
    );
    let m = detail(o.scale);
    let variants = 1 + m as usize;
    let max_tris = o.max_mesh_triangles;
    let mut sorted = defs;
    sorted.sort_by_key(|d| d.name);
    sorted
        .into_iter()
        .map(|d| {
            let index = ISLAND_ELEMENTS
                .iter()
                .position(|n| *n == d.name)
                .unwrap_or(0) as u64;
            let instances =
                (INSTANCES_AT_SCALE_1 * o.scale * d.instance_weight / w_inst).round() as u64;
            let inline_tris = INLINE_TRIANGLES_AT_SCALE_1 * o.scale * d.inline_weight / w_inline;
            let ply_tris = PLY_TRIANGLES_AT_SCALE_1 * o.scale * d.ply_weight / w_ply;
            let name = d.name;
            let mut e = ElementPlan {
                index,
                name,
                material: "sand",
                archives: Vec::new(),
                inline_files: Vec::new(),
                ply_patches: Vec::new(),
                trunk_sections: Vec::new(),
                lists: Vec::new(),
                plant: None,
            };
            let add_archives = |e: &mut ElementPlan, kind: ArchiveKind| -> Range<usize> {
                let start = e.archives.len();
                for v in 0..variants {
                    let mesh = archive_mesh(
                        kind,
                        derive_seed(o.seed, &[20, index, kind as u64, v as u64]),
                        m,
                    );
                    let object = format!("{name}_{}_{v}", kind.name());
                    e.archives.push(Archive {
                        file: format!("{name}/archives/{object}.pbrt"),
                        object,
                        material: kind.material(),
                        triangles: u64::from(mesh.triangle_count()),
                        body: ArchiveBody::Mesh(mesh),
                    });
                }
                start..e.archives.len()
            };
            let (region, surface, scatter): (Vec<Rect>, Surface, &[(ArchiveKind, f64)]) =
                match d.role {
                    Role::Terrain(material, kinds) => {
                        e.material = material;
                        (land_tiles(name, &active), Surface::Land, kinds)
                    }
                    Role::Coral => {
                        let rect = Rect {
                            x0: 1.2 * RADIUS,
                            z0: -1.2 * RADIUS,
                            x1: 1.8 * RADIUS,
                            z1: 1.2 * RADIUS,
                        };
                        (
                            vec![rect],
                            Surface::Land,
                            &[(ArchiveKind::Coral, 0.8), (ArchiveKind::Rock, 0.2)],
                        )
                    }
                    Role::Ocean => {
                        e.material = "water";
                        let rect = Rect {
                            x0: -3.0 * RADIUS,
                            z0: -3.0 * RADIUS,
                            x1: 3.0 * RADIUS,
                            z1: 3.0 * RADIUS,
                        };
                        (vec![rect], Surface::Ocean, &[])
                    }
                    Role::Plant { height, palm } => {
                        e.material = "bark";
                        let spec = TrunkSpec::new(height, palm, ply_tris, inline_tris, max_tris);
                        let object = format!("{name}_trunk");
                        let ply_files: Vec<String> = (0..spec.sections)
                            .map(|s| format!("{name}/geometry/{name}_trunk_{s:05}.ply"))
                            .collect();
                        let trunk_index = e.archives.len();
                        for (s, f) in ply_files.iter().enumerate() {
                            e.trunk_sections.push((trunk_index, s as u32, f.clone()));
                        }
                        e.archives.push(Archive {
                            file: format!("{name}/archives/{object}.pbrt"),
                            object,
                            material: "bark",
                            triangles: spec.ply_triangles() + spec.inline_triangles(),
                            body: ArchiveBody::Trunk { spec, ply_files },
                        });
                        let leaves = add_archives(
                            &mut e,
                            if palm {
                                ArchiveKind::Frond
                            } else {
                                ArchiveKind::Leaf
                            },
                        );
                        let leaves_per_plant = if palm {
                            (instances / 60).clamp(8, 200)
                        } else {
                            (instances / 40).clamp(10, 20_000)
                        };
                        let copies = (instances / (1 + leaves_per_plant)).max(1);
                        e.plant = Some((height, palm, copies));
                        e.lists.push(PlacementList {
                            kind: ListKind::PlantCopies { trunk: trunk_index },
                            files: split_files(
                                &format!("{name}/{name}_xgCopies"),
                                copies,
                                o.max_instances_per_file,
                            ),
                        });
                        e.lists.push(PlacementList {
                            kind: ListKind::PlantLeaves {
                                leaves_per_plant,
                                archives: leaves,
                            },
                            files: split_files(
                                &format!("{name}/{name}_xgLeaves"),
                                copies * leaves_per_plant,
                                o.max_instances_per_file,
                            ),
                        });
                        (Vec::new(), Surface::Land, &[])
                    }
                };
            // An element that owns no tiles has nowhere to scatter.
            let scatter = if region.is_empty() { &[] } else { scatter };
            let (inline, ply) = split_region(&region, surface, inline_tris, ply_tris, max_tris);
            // Group inline patches into files of about two meshes' worth.
            let mut file_tris = 0u64;
            for p in inline {
                if e.inline_files.is_empty() || file_tris + p.triangles() > 2 * u64::from(max_tris)
                {
                    let n = e.inline_files.len();
                    e.inline_files
                        .push((format!("{name}/{name}_geometry_{n:04}.pbrt"), Vec::new()));
                    file_tris = 0;
                }
                file_tris += p.triangles();
                if let Some(last) = e.inline_files.last_mut() {
                    last.1.push(p);
                }
            }
            for (n, p) in ply.into_iter().enumerate() {
                e.ply_patches
                    .push((format!("{name}/geometry/{name}_geometry_{n:05}.ply"), p));
            }
            let mut assigned = 0u64;
            for (i, (kind, share)) in scatter.iter().enumerate() {
                let n = if i + 1 == scatter.len() {
                    instances - assigned
                } else {
                    ((instances as f64 * share).round() as u64).min(instances - assigned)
                };
                assigned += n;
                let archives = add_archives(&mut e, *kind);
                e.lists.push(PlacementList {
                    kind: ListKind::Scatter {
                        region: region.clone(),
                        archives,
                        kind: *kind,
                    },
                    files: split_files(
                        &format!("{name}/{name}_{}", kind.list_name()),
                        n,
                        o.max_instances_per_file,
                    ),
                });
            }
            e
        })
        .collect()
}

fn plant_transform(o: &IslandOptions, terrain: &Terrain, element: u64, copy: u64) -> Affine {
    let mut rng = SplitMix64::new(derive_seed(o.seed, &[30, element, copy]));
    let (mut x, mut z) = (0.0, 0.0);
    // Rejection sampling of dry land, bounded so a line costs bounded time.
    for _ in 0..16 {
        let r = 0.92 * RADIUS * rng.next_f64().sqrt();
        let a = rng.range(0.0, TAU);
        (x, z) = (r * a.cos(), r * a.sin());
        if terrain.height(x, z) > 3.0 {
            break;
        }
    }
    Affine::translation([x, terrain.height(x, z) - 0.2, z])
        .mul(&Affine::rotation_y(rng.range(0.0, TAU)))
        .mul(&Affine::uniform_scale(rng.range(0.8, 1.2)))
}

fn leaf_transform(o: &IslandOptions, element: u64, leaf: u64, height: f64, palm: bool) -> Affine {
    let mut rng = SplitMix64::new(derive_seed(o.seed, &[31, element, leaf]));
    if palm {
        // Fronds radiate from the crown, drooping outwards.
        let top = [0.15 * height, height * rng.range(0.95, 1.0), 0.0];
        let yaw = rng.range(0.0, TAU);
        let dir = normalize([yaw.cos(), rng.range(-0.3, 0.5), yaw.sin()]);
        Affine::translation(top)
            .mul(&Affine::rotation_arc([0.0, 0.0, 1.0], dir))
            .mul(&Affine::uniform_scale(0.45 * height * rng.range(0.7, 1.1)))
    } else {
        let dir = rng.unit_vector();
        let r = rng.next_f64().cbrt();
        let pos = [
            0.35 * height * r * dir[0],
            height * (0.7 + 0.25 * r * dir[1]),
            0.35 * height * r * dir[2],
        ];
        Affine::translation(pos)
            .mul(&Affine::rotation(rng.unit_vector(), rng.range(0.0, TAU)))
            .mul(&Affine::uniform_scale(0.04 * height * rng.range(0.7, 1.3)))
    }
}

fn scatter_transform(
    o: &IslandOptions,
    terrain: &Terrain,
    element: u64,
    list: u64,
    index: u64,
    region: &[Rect],
    kind: ArchiveKind,
) -> (Affine, u64) {
    let mut rng = SplitMix64::new(derive_seed(o.seed, &[32, element, list, index]));
    let rect = region[rng.below(region.len() as u64) as usize];
    let x = rng.range(rect.x0, rect.x1);
    let z = rng.range(rect.z0, rect.z1);
    let (lo, hi) = kind.scale_range();
    let size = rng.range(lo, hi);
    let tilt = Affine::rotation(
        [rng.range(-1.0, 1.0), 0.0, rng.range(-1.0, 1.0)],
        rng.range(0.0, 0.25),
    );
    let m = Affine::translation([x, terrain.height(x, z) - 0.1 * size, z])
        .mul(&tilt)
        .mul(&Affine::rotation_y(rng.range(0.0, TAU)))
        .mul(&Affine::uniform_scale(size));
    (m, rng.next_u64())
}

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
