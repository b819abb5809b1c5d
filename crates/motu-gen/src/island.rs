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

// ---------------------------------------------------------------- terrain

/// The island's height field and ocean surface (deterministic per seed).
struct Terrain {
    noise: ValueNoise2,
    detail: ValueNoise2,
    ocean_phase: [f64; 2],
}

fn smoothstep(e0: f64, e1: f64, x: f64) -> f64 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

fn gaussian(x: f64, z: f64, cx: f64, cz: f64, sigma: f64) -> f64 {
    (-((x - cx).powi(2) + (z - cz).powi(2)) / (2.0 * sigma * sigma)).exp()
}

impl Terrain {
    fn new(seed: u64) -> Self {
        let mut rng = SplitMix64::new(derive_seed(seed, &[10]));
        Self {
            noise: ValueNoise2::new(derive_seed(seed, &[11]), 5, 1.0 / 400.0),
            detail: ValueNoise2::new(derive_seed(seed, &[12]), 3, 1.0 / 40.0),
            ocean_phase: [rng.range(0.0, TAU), rng.range(0.0, TAU)],
        }
    }

    fn height(&self, x: f64, z: f64) -> f64 {
        let r = (x * x + z * z).sqrt() / RADIUS;
        let inland = 1.0 - smoothstep(0.6, 0.95, r);
        let land = 40.0 * (1.0 - smoothstep(0.7, 1.0, r)) + 2.0 - 90.0 * smoothstep(1.0, 1.5, r);
        let mountains = 750.0 * gaussian(x, z, -550.0, -250.0, 420.0)
            + 520.0 * gaussian(x, z, 600.0, 300.0, 360.0);
        land + inland * (mountains + 40.0 * self.noise.at(x, z)) + 2.0 * self.detail.at(x, z)
    }

    fn ocean(&self, x: f64, z: f64) -> f64 {
        0.8 * (x / 37.0 + self.ocean_phase[0]).sin() * (z / 53.0 + self.ocean_phase[1]).sin()
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct Rect {
    x0: f64,
    z0: f64,
    x1: f64,
    z1: f64,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Surface {
    Land,
    Ocean,
}

/// A height-field patch: `quads_x × quads_z` quads over `rect`.
#[derive(Clone, Copy, Debug)]
struct Patch {
    rect: Rect,
    quads_x: u32,
    quads_z: u32,
    surface: Surface,
}

impl Patch {
    fn triangles(&self) -> u64 {
        2 * u64::from(self.quads_x) * u64::from(self.quads_z)
    }

    fn source<'t>(&self, terrain: &'t Terrain) -> impl TriangleSource + 't {
        let (r, surface) = (self.rect, self.surface);
        ParamGrid::new(self.quads_x + 1, self.quads_z + 1, false, move |u, v| {
            let x = r.x0 + (r.x1 - r.x0) * u;
            let z = r.z0 + (r.z1 - r.z0) * v;
            let y = match surface {
                Surface::Land => terrain.height(x, z),
                Surface::Ocean => terrain.ocean(x, z),
            };
            [x, y, z]
        })
    }
}

/// The 4×4 land tiles over [-1.2R, 1.2R]²: (primary owner, fallback owner).
const TILE_OWNERS: [[(&str, &str); 4]; 4] = [
    [
        ("isCoastline", "isBeach"),
        ("isBeach", "isBeach"),
        ("isDunesB", "isBeach"),
        ("isLavaRocks", "isBeach"),
    ],
    [
        ("isBeach", "isBeach"),
        ("isMountainA", "isMountainA"),
        ("isMountainB", "isMountainA"),
        ("isDunesA", "isBeach"),
    ],
    [
        ("isDunesA", "isBeach"),
        ("isMountainA", "isMountainA"),
        ("isMountainB", "isMountainA"),
        ("isBeach", "isBeach"),
    ],
    [
        ("isLavaRocks", "isBeach"),
        ("isDunesB", "isBeach"),
        ("isBeach", "isBeach"),
        ("isCoastline", "isBeach"),
    ],
];

fn land_tiles(owner: &str, active: &[&str]) -> Vec<Rect> {
    let size = 2.4 * RADIUS / 4.0;
    let mut out = Vec::new();
    for (iz, row) in TILE_OWNERS.iter().enumerate() {
        for (ix, (primary, fallback)) in row.iter().enumerate() {
            let resolved = [*primary, *fallback, "isBeach"]
                .into_iter()
                .find(|n| active.contains(n));
            // With only `isBeach` missing (never: it is always first) nothing owns the tile.
            if resolved == Some(owner) {
                let x0 = -1.2 * RADIUS + ix as f64 * size;
                let z0 = -1.2 * RADIUS + iz as f64 * size;
                out.push(Rect {
                    x0,
                    z0,
                    x1: x0 + size,
                    z1: z0 + size,
                });
            }
        }
    }
    out
}

/// Splits `rects` into patches: `inline_tris` and `ply_tris` spread over them,
/// every patch at most `max_tris`; returns (inline patches, PLY patches).
fn split_region(
    rects: &[Rect],
    surface: Surface,
    inline_tris: f64,
    ply_tris: f64,
    max_tris: u32,
) -> (Vec<Patch>, Vec<Patch>) {
    let mut inline = Vec::new();
    let mut ply = Vec::new();
    if rects.is_empty() {
        return (inline, ply);
    }
    let per_rect = (
        inline_tris / rects.len() as f64,
        ply_tris / rects.len() as f64,
    );
    let total = per_rect.0 + per_rect.1;
    let ply_fraction = if total > 0.0 { per_rect.1 / total } else { 0.0 };
    let max_tris = f64::from(max_tris.max(2));
    for rect in rects {
        let mut k = 2u32;
        loop {
            let cells = k * k;
            let ply_cells = (0..cells).filter(|&p| is_ply_cell(p, ply_fraction)).count() as f64;
            let inline_cells = f64::from(cells) - ply_cells;
            let per_inline = if inline_cells > 0.0 {
                per_rect.0 / inline_cells
            } else {
                0.0
            };
            let per_ply = if ply_cells > 0.0 {
                per_rect.1 / ply_cells
            } else {
                0.0
            };
            if (per_inline <= max_tris && per_ply <= max_tris) || k >= 4096 {
                let quads = |t: f64| ((t / 2.0).sqrt().round() as u32).max(1);
                let (qi, qp) = (quads(per_inline), quads(per_ply));
                for p in 0..cells {
                    let (cx, cz) = (p % k, p / k);
                    let w = (rect.x1 - rect.x0) / f64::from(k);
                    let h = (rect.z1 - rect.z0) / f64::from(k);
                    let sub = Rect {
                        x0: rect.x0 + w * f64::from(cx),
                        z0: rect.z0 + h * f64::from(cz),
                        x1: rect.x0 + w * f64::from(cx + 1),
                        z1: rect.z0 + h * f64::from(cz + 1),
                    };
                    if is_ply_cell(p, ply_fraction) {
                        ply.push(Patch {
                            rect: sub,
                            quads_x: qp,
                            quads_z: qp,
                            surface,
                        });
                    } else {
                        inline.push(Patch {
                            rect: sub,
                            quads_x: qi,
                            quads_z: qi,
                            surface,
                        });
                    }
                }
                break;
            }
            k += 1;
        }
    }
    (inline, ply)
}

/// Spreads PLY cells evenly: cell `p` is PLY when ⌊(p+1)f⌋ > ⌊pf⌋.
fn is_ply_cell(p: u32, fraction: f64) -> bool {
    ((f64::from(p) + 1.0) * fraction).floor() > (f64::from(p) * fraction).floor()
}

// ---------------------------------------------------------------- archives

/// Archive detail by scale: 1, 2 or 3.
fn detail(scale: f64) -> u32 {
    if scale < 0.01 {
        1
    } else if scale < 0.1 {
        2
    } else {
        3
    }
}

fn tube(
    r0: f64,
    r1: f64,
    length: f64,
    segments: u32,
    rows: u32,
    xf: Affine,
) -> impl TriangleSource {
    ParamGrid::new(segments, rows, true, move |u, v| {
        let r = r0 + (r1 - r0) * v;
        let a = u * TAU;
        xf.transform_point([r * a.cos(), v * length, r * a.sin()])
    })
}

fn archive_mesh(kind: ArchiveKind, seed: u64, m: u32) -> Mesh {
    let mut rng = SplitMix64::new(seed);
    let mut mesh = Mesh::default();
    match kind {
        ArchiveKind::Rock => {
            let noise = SineNoise::new(rng.next_u64(), 4, 1.5);
            let squash = rng.range(0.45, 0.8);
            let s = UvSphere::new(12 * m + 4, 6 * m + 2, move |d| {
                let r = 0.5 * (1.0 + 0.3 * noise.at(d));
                [r * d[0], squash * r * d[1] + 0.3, r * d[2]]
            });
            mesh.append(&s, &Affine::IDENTITY);
        }
        ArchiveKind::Shell => {
            let ribs = f64::from(8 + rng.below(8) as u32);
            let s = UvSphere::new(8 * m + 4, 4 * m + 2, move |d| {
                let phi = d[2].atan2(d[0]);
                let r = 0.5 * (1.0 + 0.08 * (ribs * phi).sin());
                [1.3 * r * d[0], 0.3 * r * d[1].max(-0.2) + 0.06, r * d[2]]
            });
            mesh.append(&s, &Affine::IDENTITY);
        }
        ArchiveKind::Grass => {
            for _ in 0..(4 + 3 * m) {
                let lean = rng.range(0.0, 0.5);
                let yaw = rng.range(0.0, TAU);
                let height = rng.range(0.6, 1.0);
                let blade = ParamGrid::new(2, 2 + 2 * m, false, move |u, v| {
                    let w = 0.03 * (1.0 - v);
                    [(2.0 * u - 1.0) * w, height * v, lean * v * v]
                });
                let xf = Affine::translation([rng.range(-0.15, 0.15), 0.0, rng.range(-0.15, 0.15)])
                    .mul(&Affine::rotation_y(yaw));
                mesh.append(&blade, &xf);
            }
        }
        ArchiveKind::Flower => {
            mesh.append(
                &tube(0.015, 0.01, 0.7, 4 + m, 2 + m, Affine::IDENTITY),
                &Affine::IDENTITY,
            );
            let petals = 5 + rng.below(3) as u32;
            for p in 0..petals {
                let petal = ParamGrid::new(3, 2 + m, false, |u, v| {
                    let s = 2.0 * u - 1.0;
                    [s * 0.05 * (0.2 + (PI * v).sin()), 0.04 * v * v, 0.15 * v]
                });
                let xf = Affine::translation([0.0, 0.7, 0.0])
                    .mul(&Affine::rotation_y(TAU * f64::from(p) / f64::from(petals)))
                    .mul(&Affine::rotation([1.0, 0.0, 0.0], -0.4));
                mesh.append(&petal, &xf);
            }
        }
        ArchiveKind::Coral => {
            for _ in 0..(5 + 2 * m) {
                let dir = normalize([rng.range(-0.6, 0.6), 1.0, rng.range(-0.6, 0.6)]);
                let xf = Affine::rotation_arc([0.0, 1.0, 0.0], dir);
                mesh.append(
                    &tube(0.08, 0.03, rng.range(0.5, 1.0), 4 + 2 * m, 2 + m, xf),
                    &Affine::IDENTITY,
                );
            }
        }
        ArchiveKind::Leaf => {
            let curl = rng.range(0.0, 0.2);
            let leaf = ParamGrid::new(3, 2 + m, false, move |u, v| {
                let s = 2.0 * u - 1.0;
                [
                    s * 0.15 * (0.15 + (PI * v).sin()),
                    v,
                    0.08 * s.abs() + curl * v * v,
                ]
            });
            mesh.append(&leaf, &Affine::IDENTITY);
        }
        ArchiveKind::Frond => {
            let droop = rng.range(0.2, 0.5);
            let frond = ParamGrid::new(5, 4 + 3 * m, false, move |u, v| {
                let s = 2.0 * u - 1.0;
                [s * 0.12 * (0.1 + (PI * v).sin()), -droop * v * v, v]
            });
            mesh.append(&frond, &Affine::IDENTITY);
        }
    }
    mesh
}

/// A plant's trunk: PLY sections of a tapered, bent tube plus inline branches.
#[derive(Clone, Copy, Debug)]
struct TrunkSpec {
    height: f64,
    palm: bool,
    sections: u32,
    segments: u32,
    rows_per_section: u32,
    branches: u32,
    branch_segments: u32,
    branch_rows: u32,
}

impl TrunkSpec {
    fn new(height: f64, palm: bool, ply_tris: f64, inline_tris: f64, max_tris: u32) -> Self {
        let max = f64::from(max_tris.max(64));
        let sections = (ply_tris / max).ceil().max(1.0) as u32;
        let per = ply_tris / f64::from(sections);
        let segments = (((per / 2.0).sqrt() / 2.0).round() as u32).clamp(6, 4096);
        let rows_per_section = ((per / (2.0 * f64::from(segments))).round() as u32 + 1).max(2);
        let branches = ((inline_tris / max).ceil() as u32).max(if palm { 0 } else { 5 });
        let per_branch = if branches > 0 {
            inline_tris / f64::from(branches)
        } else {
            0.0
        };
        let branch_segments = (((per_branch / 2.0).sqrt() / 3.0).round() as u32).clamp(4, 4096);
        let branch_rows =
            ((per_branch / (2.0 * f64::from(branch_segments))).round() as u32 + 1).max(2);
        Self {
            height,
            palm,
            sections,
            segments,
            rows_per_section,
            branches,
            branch_segments,
            branch_rows,
        }
    }

    fn section(&self, index: u32) -> impl TriangleSource {
        let spec = *self;
        ParamGrid::new(
            spec.segments,
            spec.rows_per_section,
            true,
            move |u, v_local| {
                let v = (f64::from(index) + v_local) / f64::from(spec.sections);
                let r = spec.height
                    * if spec.palm {
                        0.025 - 0.01 * v
                    } else {
                        0.05 - 0.035 * v
                    };
                let bend = if spec.palm {
                    0.15 * spec.height * v * v
                } else {
                    0.02 * spec.height * (5.0 * v).sin()
                };
                let a = u * TAU;
                [r * a.cos() + bend, v * spec.height, r * a.sin()]
            },
        )
    }

    fn branch(&self, index: u32) -> impl TriangleSource {
        let h = self.height;
        let t = f64::from(index) / f64::from(self.branches.max(1));
        let yaw = f64::from(index) * 2.4;
        let dir = normalize([yaw.cos(), 0.7, yaw.sin()]);
        let xf = Affine::translation([0.0, h * (0.4 + 0.45 * t), 0.0])
            .mul(&Affine::rotation_arc([0.0, 1.0, 0.0], dir));
        tube(
            0.02 * h,
            0.005 * h,
            0.3 * h,
            self.branch_segments,
            self.branch_rows,
            xf,
        )
    }

    fn ply_triangles(&self) -> u64 {
        u64::from(self.section(0).triangle_count()) * u64::from(self.sections)
    }

    fn inline_triangles(&self) -> u64 {
        if self.branches == 0 {
            0
        } else {
            u64::from(self.branch(0).triangle_count()) * u64::from(self.branches)
        }
    }
}

enum ArchiveBody {
    Mesh(Mesh),
    /// The trunk; PLY sections are separate files.
    Trunk {
        spec: TrunkSpec,
        ply_files: Vec<String>,
    },
}

struct Archive {
    object: String,
    file: String,
    material: &'static str,
    body: ArchiveBody,
    triangles: u64,
}

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

// ---------------------------------------------------------------- writers

fn cameras(terrain: &Terrain) -> Vec<(&'static str, CameraSpec)> {
    let ground = |x: f64, z: f64, above: f64| [x, terrain.height(x, z).max(0.0) + above, z];
    ISLAND_CAMERAS
        .iter()
        .map(|&name| {
            let spec = match name {
                "shotCam" => CameraSpec {
                    eye: [-400.0, 260.0, 3700.0],
                    target: [0.0, 260.0, 0.0],
                    fov_deg: 32.0,
                },
                "beachCam" => CameraSpec {
                    eye: ground(300.0, 1950.0, 8.0),
                    target: ground(-900.0, 1500.0, 10.0),
                    fov_deg: 40.0,
                },
                "birdseyeCam" => CameraSpec {
                    eye: [0.0, 7000.0, 200.0],
                    target: [0.0, 0.0, 0.0],
                    fov_deg: 45.0,
                },
                "dunesACam" => CameraSpec {
                    eye: ground(1400.0, -300.0, 6.0),
                    target: ground(1800.0, -700.0, 2.0),
                    fov_deg: 45.0,
                },
                // Close-ups, as Moana's are: each sees a small part of the island (what
                // out-of-core streaming needs). grassCam and rootsCam look down at a few metres
                // of ground; palmsCam looks down on the hills near the centre from above the
                // palms, close enough to the scene's centre that a dolly towards it (`motu
                // render --frames`) stays above ground.
                "grassCam" => CameraSpec {
                    eye: ground(-900.0, 600.0, 4.0),
                    target: ground(-903.0, 597.0, 0.0),
                    fov_deg: 50.0,
                },
                "palmsCam" => CameraSpec {
                    eye: ground(150.0, 250.0, 120.0),
                    target: ground(100.0, 170.0, 0.0),
                    fov_deg: 30.0,
                },
                _ => CameraSpec {
                    eye: ground(-300.0, 1200.0, 3.0),
                    target: ground(-301.0, 1198.5, 0.0),
                    fov_deg: 60.0,
                },
            };
            (name, spec)
        })
        .collect()
}

fn write_scene_file(
    o: &IslandOptions,
    ctx: &Ctx<'_>,
    elements: &[ElementPlan],
) -> Result<Tally, GenError> {
    let syntax = Syntax::V3;
    let mut out = OutFile::create(ctx.root, "scene.pbrt", ctx.live)?;
    let mut line = Vec::new();
    line.extend_from_slice(
        format!(
            "# motu gen island: scale {} seed {} ({} elements). Standard pbrt-v3, Moana-like layout.\n",
            o.scale,
            o.seed,
            elements.len()
        )
        .as_bytes(),
    );
    push_film(&mut line, syntax, o.width, o.height, "island.exr");
    for cam in ISLAND_CAMERAS {
        line.extend_from_slice(format!("Include \"cameras/{cam}.pbrt\"\n").as_bytes());
    }
    line.extend_from_slice(b"\nWorldBegin\n\n");
    push_sun(&mut line, syntax, [0.35, 1.0, 0.55], [3.0, 2.9, 2.7]);
    for (name, rgb) in MATERIALS {
        push_material(&mut line, syntax, name, rgb);
    }
    line.push(b'\n');
    for e in elements {
        line.extend_from_slice(format!("Include \"{0}/{0}.pbrt\"\n", e.name).as_bytes());
    }
    line.extend_from_slice(b"\nWorldEnd\n");
    out.drain(&mut line)?;
    Ok(Tally::file(out.finish()?))
}

fn write_camera_file(ctx: &Ctx<'_>, name: &str, spec: &CameraSpec) -> Result<Tally, GenError> {
    let mut out = OutFile::create(ctx.root, &format!("cameras/{name}.pbrt"), ctx.live)?;
    // Identity: several camera files are included in a row, and LookAt composes.
    let mut line = format!("# {name}\nIdentity\n").into_bytes();
    push_camera(&mut line, spec);
    out.drain(&mut line)?;
    Ok(Tally::file(out.finish()?))
}

fn write_element_file(
    o: &IslandOptions,
    ctx: &Ctx<'_>,
    e: &ElementPlan,
) -> Result<Tally, GenError> {
    let mut out = OutFile::create(ctx.root, &format!("{0}/{0}.pbrt", e.name), ctx.live)?;
    let mut s = format!("# element {}\nAttributeBegin\n", e.name);
    for a in &e.archives {
        s += &format!("Include \"{}\"\n", a.file);
    }
    s += &format!("AttributeBegin\nNamedMaterial \"{}\"\n", e.material);
    let terrain =
        e.inline_files
            .iter()
            .map(|(file, _)| format!("Include \"{file}\"\n"))
            .chain(e.ply_patches.iter().map(|(file, _)| {
                format!("Shape \"plymesh\" \"string filename\" [ \"{file}\" ]\n")
            }));
    let mut terrain_instances = 0u64;
    for (n, shapes) in terrain.enumerate() {
        if o.terrain_objects {
            // One object per geometry file, instanced once in place (the CTM is the identity).
            let object = format!("{}_terrain_{n:05}", e.name);
            s += &format!(
                "ObjectBegin \"{object}\"\n{shapes}ObjectEnd\nObjectInstance \"{object}\"\n"
            );
            terrain_instances += 1;
        } else {
            s += &shapes;
        }
    }
    s += "AttributeEnd\n";
    for list in &e.lists {
        for (file, _) in &list.files {
            s += &format!("Include \"{file}\"\n");
        }
    }
    s += "AttributeEnd\n";
    out.write_str(&s)?;
    Ok(Tally {
        object_instances: terrain_instances,
        flattened_instances: terrain_instances,
        ..Tally::file(out.finish()?)
    })
}

fn write_archive_file(ctx: &Ctx<'_>, a: &Archive) -> Result<Tally, GenError> {
    let mut out = OutFile::create(ctx.root, &a.file, ctx.live)?;
    let mut line = format!(
        "ObjectBegin \"{}\"\nNamedMaterial \"{}\"\n",
        a.object, a.material
    )
    .into_bytes();
    out.drain(&mut line)?;
    let unique = match &a.body {
        ArchiveBody::Mesh(mesh) => {
            write_trianglemesh(&mut out, mesh, Syntax::V3, 4, &mut line)?;
            a.triangles
        }
        ArchiveBody::Trunk { spec, ply_files } => {
            for f in ply_files {
                out.write_str(&format!(
                    "Shape \"plymesh\" \"string filename\" [ \"{f}\" ]\n"
                ))?;
            }
            for b in 0..spec.branches {
                write_trianglemesh(&mut out, &spec.branch(b), Syntax::V3, 4, &mut line)?;
            }
            // PLY sections count themselves.
            spec.inline_triangles()
        }
    };
    out.write_str("ObjectEnd\n")?;
    Ok(Tally {
        unique_triangles: unique,
        ..Tally::file(out.finish()?)
    })
}

fn write_inline_file(
    ctx: &Ctx<'_>,
    terrain: &Terrain,
    file: &str,
    patches: &[Patch],
) -> Result<Tally, GenError> {
    let mut out = OutFile::create(ctx.root, file, ctx.live)?;
    let mut line = Vec::with_capacity(1 << 16);
    let mut triangles = 0;
    for p in patches {
        write_trianglemesh(
            &mut out,
            &p.source(terrain),
            Syntax::V3,
            POSITION_DECIMALS,
            &mut line,
        )?;
        triangles += p.triangles();
    }
    Ok(Tally {
        unique_triangles: triangles,
        instanced_triangles: triangles,
        ..Tally::file(out.finish()?)
    })
}

fn write_placements(
    o: &IslandOptions,
    ctx: &Ctx<'_>,
    terrain: &Terrain,
    e: &ElementPlan,
    list_index: usize,
    file: &str,
    range: Range<u64>,
) -> Result<Tally, GenError> {
    let list = &e.lists[list_index];
    let mut out = OutFile::create(ctx.root, file, ctx.live)?;
    let mut line = Vec::with_capacity(1 << 16);
    let mut instanced = 0u64;
    let (height, palm, _) = e.plant.unwrap_or((1.0, false, 0));
    let mut cached_copy: Option<(u64, Affine)> = None;
    for k in range.clone() {
        let (m, archive) = match &list.kind {
            ListKind::Scatter {
                region,
                archives,
                kind,
            } => {
                let (m, pick) =
                    scatter_transform(o, terrain, e.index, list_index as u64, k, region, *kind);
                (
                    m,
                    archives.start + (pick % archives.len().max(1) as u64) as usize,
                )
            }
            ListKind::PlantCopies { trunk } => (plant_transform(o, terrain, e.index, k), *trunk),
            ListKind::PlantLeaves {
                leaves_per_plant,
                archives,
            } => {
                let (copy, leaf) = (k / leaves_per_plant, k % leaves_per_plant);
                let world_from_plant = match cached_copy {
                    Some((c, m)) if c == copy => m,
                    _ => {
                        let m = plant_transform(o, terrain, e.index, copy);
                        cached_copy = Some((copy, m));
                        m
                    }
                };
                let plant_from_leaf = leaf_transform(o, e.index, leaf, height, palm);
                let pick = archives.start + (leaf % archives.len().max(1) as u64) as usize;
                (world_from_plant.mul(&plant_from_leaf), pick)
            }
        };
        let a = &e.archives[archive];
        push_instance(&mut line, &m, &a.object, POSITION_DECIMALS);
        instanced += a.triangles;
        if line.len() >= 60_000 {
            out.drain(&mut line)?;
        }
    }
    out.drain(&mut line)?;
    let n = range.end - range.start;
    Ok(Tally {
        object_instances: n,
        flattened_instances: n,
        instanced_triangles: instanced,
        ..Tally::file(out.finish()?)
    })
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
mod tests {
    use super::*;
    use crate::testutil::{check_scene, hash_dir};
    use crate::{generate as gen, GenKind};

    fn tiny(scale: f64) -> IslandOptions {
        IslandOptions {
            scale,
            max_instances_per_file: 1_500,
            max_mesh_triangles: 4_000,
            ..IslandOptions::default()
        }
    }

    #[test]
    fn default_island_is_standard_v3_and_counts_match_the_files() {
        let dir = tempfile::tempdir().expect("tempdir");
        let s = gen(&GenKind::Island(tiny(0.0002)), dir.path(), &mut |_| {}).expect("generate");
        let p = check_scene(&s.scene_path);
        assert!(!p.nested, "island must be single-level pbrt-v3");
        assert!(!p.v4_only_syntax && p.v3_only_syntax && p.world_end);
        assert_eq!(p.object_instances, s.object_instances);
        assert_eq!(p.flattened_instances, s.flattened_instances);
        assert_eq!(p.unique_triangles, s.unique_triangles);
        assert_eq!(p.instanced_triangles, s.instanced_triangles);
        assert_eq!(p.files, s.files_written);
        assert_eq!(p.bytes, s.bytes_written);
        assert_eq!(p.cameras, 7);
        assert_eq!(p.elements, s.elements);
        assert_eq!(
            s.elements,
            ["isBeach", "isCoral", "isMountainA", "isPalmRig", "osOcean"]
        );
        let expected = INSTANCES_AT_SCALE_1 * 0.0002;
        let ratio = s.object_instances as f64 / expected;
        assert!(
            (0.8..1.2).contains(&ratio),
            "{} instances for {expected}",
            s.object_instances
        );
        // Small limits force split placement files and split meshes.
        assert!(
            std::fs::read_dir(dir.path().join("isBeach"))
                .map(|d| d.count())
                .unwrap_or(0)
                > 4
        );
    }

    #[test]
    fn every_element_and_camera_is_written_at_full_element_count() {
        let dir = tempfile::tempdir().expect("tempdir");
        let o = IslandOptions {
            elements: Some(20),
            ..tiny(0.0001)
        };
        let s = gen(&GenKind::Island(o), dir.path(), &mut |_| {}).expect("generate");
        let p = check_scene(&s.scene_path);
        assert_eq!(s.elements.len(), 20);
        assert_eq!(p.elements.len(), 20);
        assert_eq!(p.object_instances, s.object_instances);
        for cam in ISLAND_CAMERAS {
            assert!(dir.path().join(format!("cameras/{cam}.pbrt")).is_file());
        }
        let scene = std::fs::read_to_string(&s.scene_path).unwrap_or_default();
        let shot = scene.find("shotCam").unwrap_or(0);
        assert!(
            ISLAND_CAMERAS
                .iter()
                .all(|c| scene.find(c).unwrap_or(usize::MAX) <= shot),
            "shotCam included last"
        );
    }

    #[test]
    fn deterministic_across_thread_counts_and_scales_linearly() {
        let a = tempfile::tempdir().expect("tempdir");
        let b = tempfile::tempdir().expect("tempdir");
        let c = tempfile::tempdir().expect("tempdir");
        let sa = gen(
            &GenKind::Island(IslandOptions {
                threads: Some(1),
                ..tiny(0.0001)
            }),
            a.path(),
            &mut |_| {},
        )
        .expect("a");
        let mut reports = 0;
        let sb = gen(
            &GenKind::Island(IslandOptions {
                threads: Some(3),
                ..tiny(0.0001)
            }),
            b.path(),
            &mut |_| reports += 1,
        )
        .expect("b");
        assert!(reports >= 1);
        assert_eq!(hash_dir(a.path()), hash_dir(b.path()));
        assert_eq!(
            GenSummary {
                scene_path: sb.scene_path.clone(),
                ..sa.clone()
            },
            sb
        );
        let sc = gen(&GenKind::Island(tiny(0.0004)), c.path(), &mut |_| {}).expect("c");
        let ratio = sc.object_instances as f64 / sa.object_instances as f64;
        assert!((3.2..4.8).contains(&ratio), "instances scale: {ratio}");
        let ratio = sc.bytes_written as f64 / sa.bytes_written as f64;
        assert!((2.5..5.0).contains(&ratio), "bytes scale: {ratio}");
    }

    #[test]
    fn plants_stand_on_land_and_patches_respect_the_mesh_limit() {
        let terrain = Terrain::new(1);
        let o = IslandOptions::default();
        for c in 0..50 {
            let m = plant_transform(&o, &terrain, 2, c);
            let [x, y, z] = m.translation;
            assert!((y - (terrain.height(x, z) - 0.2)).abs() < 1e-9);
        }
        let rect = Rect {
            x0: 0.0,
            z0: 0.0,
            x1: 10.0,
            z1: 10.0,
        };
        let (inline, ply) = split_region(&[rect], Surface::Land, 50_000.0, 30_000.0, 4_000);
        assert!(inline.iter().chain(&ply).all(|p| p.triangles() <= 4_200));
        let total: u64 = inline.iter().chain(&ply).map(Patch::triangles).sum();
        assert!((60_000..100_000).contains(&total), "{total}");
        assert!(!ply.is_empty() && !inline.is_empty());
    }

    #[test]
    fn terrain_objects_instance_each_patch_once_and_counts_still_match() {
        let dir = tempfile::tempdir().expect("tempdir");
        let plain = tempfile::tempdir().expect("tempdir");
        let o = tiny(0.0002);
        let a = gen(&GenKind::Island(o.clone()), plain.path(), &mut |_| {}).expect("plain");
        let s = gen(
            &GenKind::Island(IslandOptions {
                terrain_objects: true,
                ..o.clone()
            }),
            dir.path(),
            &mut |_| {},
        )
        .expect("objects");
        let p = check_scene(&s.scene_path);
        assert!(!p.nested, "still single-level pbrt-v3");
        assert_eq!(p.object_instances, s.object_instances);
        assert_eq!(p.flattened_instances, s.flattened_instances);
        assert_eq!(p.unique_triangles, s.unique_triangles);
        assert_eq!(p.instanced_triangles, s.instanced_triangles);
        // One instance per terrain geometry file, the same triangles.
        let files: usize = plan(&o)
            .iter()
            .map(|e| e.inline_files.len() + e.ply_patches.len())
            .sum();
        assert!(files > 8, "{files}");
        assert_eq!(s.object_instances, a.object_instances + files as u64);
        assert_eq!(s.unique_triangles, a.unique_triangles);
        assert_eq!(s.instanced_triangles, a.instanced_triangles);
        let beach =
            std::fs::read_to_string(dir.path().join("isBeach/isBeach.pbrt")).unwrap_or_default();
        assert!(
            beach.contains("ObjectBegin \"isBeach_terrain_00000\""),
            "{beach}"
        );
    }

    #[test]
    fn close_up_cameras_look_down_at_the_ground_nearby() {
        let terrain = Terrain::new(1);
        for (name, c) in cameras(&terrain) {
            if !["grassCam", "rootsCam", "palmsCam"].contains(&name) {
                continue;
            }
            let d = [
                c.target[0] - c.eye[0],
                c.target[1] - c.eye[1],
                c.target[2] - c.eye[2],
            ];
            let horizontal = (d[0] * d[0] + d[2] * d[2]).sqrt();
            // Pitched down by more than half the field of view: no ray reaches the horizon.
            let pitch_down = (-d[1]).atan2(horizontal).to_degrees();
            assert!(pitch_down > 0.5 * c.fov_deg + 10.0, "{name}: {pitch_down}");
            let above = c.eye[1] - terrain.height(c.eye[0], c.eye[2]).max(0.0);
            assert!((1.0..=150.0).contains(&above), "{name}: {above}");
        }
    }

    #[test]
    fn rejects_bad_options() {
        let dir = tempfile::tempdir().expect("tempdir");
        for o in [
            IslandOptions {
                scale: 0.0,
                ..IslandOptions::default()
            },
            IslandOptions {
                scale: f64::NAN,
                ..IslandOptions::default()
            },
            IslandOptions {
                elements: Some(21),
                ..IslandOptions::default()
            },
            IslandOptions {
                max_instances_per_file: 0,
                ..IslandOptions::default()
            },
        ] {
            assert!(matches!(
                gen(&GenKind::Island(o), dir.path(), &mut |_| {}),
                Err(GenError::InvalidOption { .. })
            ));
        }
    }
}
