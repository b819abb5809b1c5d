//! The island's terrain: height field, land tiles per element, and the patches they split into.

use super::*;

/// The island's height field and ocean surface (deterministic per seed).
pub(super) struct Terrain {
    pub(super) noise: ValueNoise2,
    pub(super) detail: ValueNoise2,
    pub(super) ocean_phase: [f64; 2],
}

pub(super) fn smoothstep(e0: f64, e1: f64, x: f64) -> f64 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

pub(super) fn gaussian(x: f64, z: f64, cx: f64, cz: f64, sigma: f64) -> f64 {
    (-((x - cx).powi(2) + (z - cz).powi(2)) / (2.0 * sigma * sigma)).exp()
}

impl Terrain {
    pub(super) fn new(seed: u64) -> Self {
        let mut rng = SplitMix64::new(derive_seed(seed, &[10]));
        Self {
            noise: ValueNoise2::new(derive_seed(seed, &[11]), 5, 1.0 / 400.0),
            detail: ValueNoise2::new(derive_seed(seed, &[12]), 3, 1.0 / 40.0),
            ocean_phase: [rng.range(0.0, TAU), rng.range(0.0, TAU)],
        }
    }

    pub(super) fn height(&self, x: f64, z: f64) -> f64 {
        let r = (x * x + z * z).sqrt() / RADIUS;
        let inland = 1.0 - smoothstep(0.6, 0.95, r);
        let land = 40.0 * (1.0 - smoothstep(0.7, 1.0, r)) + 2.0 - 90.0 * smoothstep(1.0, 1.5, r);
        let mountains = 750.0 * gaussian(x, z, -550.0, -250.0, 420.0)
            + 520.0 * gaussian(x, z, 600.0, 300.0, 360.0);
        land + inland * (mountains + 40.0 * self.noise.at(x, z)) + 2.0 * self.detail.at(x, z)
    }

    pub(super) fn ocean(&self, x: f64, z: f64) -> f64 {
        0.8 * (x / 37.0 + self.ocean_phase[0]).sin() * (z / 53.0 + self.ocean_phase[1]).sin()
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Rect {
    pub(super) x0: f64,
    pub(super) z0: f64,
    pub(super) x1: f64,
    pub(super) z1: f64,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Surface {
    Land,
    Ocean,
}

/// A height-field patch: `quads_x × quads_z` quads over `rect`.
#[derive(Clone, Copy, Debug)]
pub(super) struct Patch {
    pub(super) rect: Rect,
    pub(super) quads_x: u32,
    pub(super) quads_z: u32,
    pub(super) surface: Surface,
}

impl Patch {
    pub(super) fn triangles(&self) -> u64 {
        2 * u64::from(self.quads_x) * u64::from(self.quads_z)
    }

    pub(super) fn source<'t>(&self, terrain: &'t Terrain) -> impl TriangleSource + 't {
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
pub(super) const TILE_OWNERS: [[(&str, &str); 4]; 4] = [
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

pub(super) fn land_tiles(owner: &str, active: &[&str]) -> Vec<Rect> {
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
pub(super) fn split_region(
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
pub(super) fn is_ply_cell(p: u32, fraction: f64) -> bool {
    ((f64::from(p) + 1.0) * fraction).floor() > (f64::from(p) * fraction).floor()
}
