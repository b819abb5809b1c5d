//! Procedural triangle meshes, all random-access so they stream to disk
//! without being materialised (a terrain patch of a million triangles costs
//! no memory), and their writers: inline pbrt `trianglemesh` and binary PLY.

use std::f64::consts::{PI, TAU};
use std::path::Path;

use crate::math::{Affine, Vec3};
use crate::pbrt::Syntax;
use crate::text::{push_fixed, push_u64, LiveCounters, OutFile};
use crate::GenError;

/// A triangle mesh whose vertices and triangles can be computed by index.
pub(crate) trait TriangleSource: Sync {
    fn vertex_count(&self) -> u32;
    fn triangle_count(&self) -> u32;
    fn vertex(&self, index: u32) -> Vec3;
    fn triangle(&self, index: u32) -> [u32; 3];
}

/// A `columns × rows` vertex grid over (u, v) ∈ [0,1]², optionally wrapped in
/// u (cylinders): `position(u, v)` places each vertex.
pub(crate) struct ParamGrid<F> {
    pub(crate) columns: u32,
    pub(crate) rows: u32,
    pub(crate) wrap_u: bool,
    pub(crate) position: F,
}

impl<F: Fn(f64, f64) -> Vec3 + Sync> ParamGrid<F> {
    pub(crate) fn new(columns: u32, rows: u32, wrap_u: bool, position: F) -> Self {
        // At least one quad, and a wrapped grid needs three columns.
        let columns = columns.max(if wrap_u { 3 } else { 2 });
        Self {
            columns,
            rows: rows.max(2),
            wrap_u,
            position,
        }
    }

    fn quads_per_row(&self) -> u32 {
        if self.wrap_u {
            self.columns
        } else {
            self.columns - 1
        }
    }
}

impl<F: Fn(f64, f64) -> Vec3 + Sync> TriangleSource for ParamGrid<F> {
    fn vertex_count(&self) -> u32 {
        self.columns * self.rows
    }

    fn triangle_count(&self) -> u32 {
        2 * self.quads_per_row() * (self.rows - 1)
    }

    fn vertex(&self, index: u32) -> Vec3 {
        let iu = index % self.columns;
        let iv = index / self.columns;
        let u = if self.wrap_u {
            f64::from(iu) / f64::from(self.columns)
        } else {
            f64::from(iu) / f64::from(self.columns - 1)
        };
        let v = f64::from(iv) / f64::from(self.rows - 1);
        (self.position)(u, v)
    }

    fn triangle(&self, index: u32) -> [u32; 3] {
        let cell = index / 2;
        let q = self.quads_per_row();
        let cu = cell % q;
        let cv = cell / q;
        let a = cv * self.columns + cu;
        let b = cv * self.columns + (cu + 1) % self.columns;
        let c = a + self.columns;
        let d = b + self.columns;
        if index % 2 == 0 {
            [a, b, d]
        } else {
            [a, d, c]
        }
    }
}

/// A UV sphere with single pole vertices (no degenerate triangles):
/// `position(unit_dir)` places each vertex, e.g. a displaced radius.
pub(crate) struct UvSphere<F> {
    pub(crate) segments: u32,
    pub(crate) rings: u32,
    pub(crate) position: F,
}

impl<F: Fn(Vec3) -> Vec3 + Sync> UvSphere<F> {
    pub(crate) fn new(segments: u32, rings: u32, position: F) -> Self {
        Self {
            segments: segments.max(3),
            rings: rings.max(2),
            position,
        }
    }
}

impl<F: Fn(Vec3) -> Vec3 + Sync> TriangleSource for UvSphere<F> {
    fn vertex_count(&self) -> u32 {
        2 + (self.rings - 1) * self.segments
    }

    fn triangle_count(&self) -> u32 {
        2 * self.segments * (self.rings - 1)
    }

    fn vertex(&self, index: u32) -> Vec3 {
        let last = self.vertex_count() - 1;
        let dir = if index == 0 {
            [0.0, 1.0, 0.0]
        } else if index == last {
            [0.0, -1.0, 0.0]
        } else {
            let ring = (index - 1) / self.segments + 1;
            let seg = (index - 1) % self.segments;
            let theta = PI * f64::from(ring) / f64::from(self.rings);
            let phi = TAU * f64::from(seg) / f64::from(self.segments);
            [
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin(),
            ]
        };
        (self.position)(dir)
    }

    fn triangle(&self, index: u32) -> [u32; 3] {
        let s = self.segments;
        let ring_vertex = |ring: u32, seg: u32| 1 + (ring - 1) * s + seg % s;
        if index < s {
            return [0, ring_vertex(1, index + 1), ring_vertex(1, index)];
        }
        let bands = 2 * s * (self.rings - 2);
        let i = index - s;
        if i < bands {
            let ring = i / (2 * s) + 1;
            let seg = (i / 2) % s;
            let a = ring_vertex(ring, seg);
            let b = ring_vertex(ring, seg + 1);
            let c = ring_vertex(ring + 1, seg);
            let d = ring_vertex(ring + 1, seg + 1);
            return if i % 2 == 0 { [a, b, d] } else { [a, d, c] };
        }
        let seg = i - bands;
        let south = self.vertex_count() - 1;
        [
            south,
            ring_vertex(self.rings - 1, seg),
            ring_vertex(self.rings - 1, seg + 1),
        ]
    }
}

/// A small materialised mesh, for archives assembled from several parts.
#[derive(Clone, Debug, Default)]
pub(crate) struct Mesh {
    pub(crate) positions: Vec<[f32; 3]>,
    pub(crate) triangles: Vec<[u32; 3]>,
}

impl Mesh {
    /// Appends `part` transformed by `parent_from_part`.
    pub(crate) fn append(&mut self, part: &dyn TriangleSource, parent_from_part: &Affine) {
        let base = self.positions.len() as u32;
        for i in 0..part.vertex_count() {
            let p = parent_from_part.transform_point(part.vertex(i));
            self.positions.push([p[0] as f32, p[1] as f32, p[2] as f32]);
        }
        for t in 0..part.triangle_count() {
            let [a, b, c] = part.triangle(t);
            self.triangles.push([a + base, b + base, c + base]);
        }
    }
}

impl TriangleSource for Mesh {
    fn vertex_count(&self) -> u32 {
        self.positions.len() as u32
    }

    fn triangle_count(&self) -> u32 {
        self.triangles.len() as u32
    }

    fn vertex(&self, index: u32) -> Vec3 {
        let p = self.positions[index as usize];
        [f64::from(p[0]), f64::from(p[1]), f64::from(p[2])]
    }

    fn triangle(&self, index: u32) -> [u32; 3] {
        self.triangles[index as usize]
    }
}

/// Numbers per text line in inline arrays: short lines for editors, few newlines.
const VALUES_PER_LINE: u32 = 4;

/// Writes `Shape "trianglemesh"` with the mesh inline, positions rounded to
/// `decimals`. Streams: memory use is one line buffer.
pub(crate) fn write_trianglemesh(
    out: &mut OutFile<'_>,
    mesh: &dyn TriangleSource,
    syntax: Syntax,
    decimals: u32,
    line: &mut Vec<u8>,
) -> Result<(), GenError> {
    line.clear();
    line.extend_from_slice(b"Shape \"trianglemesh\"\n  \"integer indices\" [\n");
    for t in 0..mesh.triangle_count() {
        let [a, b, c] = mesh.triangle(t);
        line.extend_from_slice(b"    ");
        push_u64(line, u64::from(a));
        line.push(b' ');
        push_u64(line, u64::from(b));
        line.push(b' ');
        push_u64(line, u64::from(c));
        if t % VALUES_PER_LINE == VALUES_PER_LINE - 1 || t + 1 == mesh.triangle_count() {
            line.push(b'\n');
            out.drain(line)?;
        }
    }
    line.extend_from_slice(b"  ]\n  \"");
    line.extend_from_slice(syntax.point_type().as_bytes());
    line.extend_from_slice(b" P\" [\n");
    for v in 0..mesh.vertex_count() {
        let p = mesh.vertex(v);
        line.extend_from_slice(b"    ");
        push_fixed(line, p[0], decimals);
        line.push(b' ');
        push_fixed(line, p[1], decimals);
        line.push(b' ');
        push_fixed(line, p[2], decimals);
        if v % VALUES_PER_LINE == VALUES_PER_LINE - 1 || v + 1 == mesh.vertex_count() {
            line.push(b'\n');
            out.drain(line)?;
        }
    }
    line.extend_from_slice(b"  ]\n");
    out.drain(line)
}

/// Writes `root/relative` as a binary little-endian PLY (float x y z; faces as
/// `uchar` count + `int` indices, the layout pbrt and rply read) and returns
/// its size in bytes.
pub(crate) fn write_ply(
    root: &Path,
    relative: &str,
    mesh: &dyn TriangleSource,
    live: &LiveCounters,
) -> Result<u64, GenError> {
    let mut out = OutFile::create(root, relative, live)?;
    let header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment generated by motu-gen\n\
         element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        mesh.vertex_count(),
        mesh.triangle_count()
    );
    out.write_str(&header)?;
    let mut buf: Vec<u8> = Vec::with_capacity(64 << 10);
    for v in 0..mesh.vertex_count() {
        for c in mesh.vertex(v) {
            buf.extend_from_slice(&(c as f32).to_le_bytes());
        }
        if buf.len() >= 60 << 10 {
            out.drain(&mut buf)?;
        }
    }
    for t in 0..mesh.triangle_count() {
        buf.push(3);
        for i in mesh.triangle(t) {
            buf.extend_from_slice(&(i as i32).to_le_bytes());
        }
        if buf.len() >= 60 << 10 {
            out.drain(&mut buf)?;
        }
    }
    out.drain(&mut buf)?;
    out.finish()
}

/// Smooth deterministic pseudo-noise in [-1, 1]: a sum of sines with
/// per-seed phases (cheap, no tables, good enough for rocks and terrain).
#[derive(Clone, Debug)]
pub(crate) struct SineNoise {
    waves: Vec<(Vec3, f64, f64)>, // (frequency vector, phase, amplitude)
    norm: f64,
}

impl SineNoise {
    pub(crate) fn new(seed: u64, octaves: u32, base_frequency: f64) -> Self {
        let mut rng = crate::rng::SplitMix64::new(seed);
        let mut waves = Vec::new();
        let mut norm = 0.0;
        for octave in 0..octaves {
            let f = base_frequency * f64::from(1u32 << octave.min(20));
            let amplitude = 1.0 / f64::from(1u32 << octave.min(20));
            for _ in 0..3 {
                let dir = rng.unit_vector();
                waves.push((crate::math::scale(dir, f), rng.range(0.0, TAU), amplitude));
                norm += amplitude;
            }
        }
        Self {
            waves,
            norm: if norm > 0.0 { norm } else { 1.0 },
        }
    }

    pub(crate) fn at(&self, p: Vec3) -> f64 {
        self.waves
            .iter()
            .map(|(k, phase, a)| a * (crate::math::dot(*k, p) + phase).sin())
            .sum::<f64>()
            / self.norm
    }
}

/// 2D value noise in [-1, 1] (hashed lattice, smooth interpolation, fBm
/// octaves): ~10x cheaper than `SineNoise` per sample, for height fields
/// evaluated once per vertex and per placed instance.
#[derive(Clone, Debug)]
pub(crate) struct ValueNoise2 {
    seed: u64,
    octaves: u32,
    frequency: f64,
}

impl ValueNoise2 {
    pub(crate) fn new(seed: u64, octaves: u32, frequency: f64) -> Self {
        Self {
            seed,
            octaves: octaves.max(1),
            frequency,
        }
    }

    fn lattice(&self, octave: u32, ix: i64, iz: i64) -> f64 {
        let h = crate::rng::mix64(
            self.seed
                ^ (ix as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
                ^ (iz as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
                ^ u64::from(octave).wrapping_mul(0x1656_67B1_9E37_79F9),
        );
        (h >> 11) as f64 * (2.0 / (1u64 << 53) as f64) - 1.0
    }

    pub(crate) fn at(&self, x: f64, z: f64) -> f64 {
        let (mut sum, mut norm, mut amplitude, mut f) = (0.0, 0.0, 1.0, self.frequency);
        for octave in 0..self.octaves {
            let (fx, fz) = (x * f, z * f);
            let (x0, z0) = (fx.floor(), fz.floor());
            let (tx, tz) = (fx - x0, fz - z0);
            let (sx, sz) = (tx * tx * (3.0 - 2.0 * tx), tz * tz * (3.0 - 2.0 * tz));
            let (ix, iz) = (x0 as i64, z0 as i64);
            let a = self.lattice(octave, ix, iz);
            let b = self.lattice(octave, ix + 1, iz);
            let c = self.lattice(octave, ix, iz + 1);
            let d = self.lattice(octave, ix + 1, iz + 1);
            let top = a + (b - a) * sx;
            let bottom = c + (d - c) * sx;
            sum += amplitude * (top + (bottom - top) * sz);
            norm += amplitude;
            amplitude *= 0.5;
            f *= 2.0;
        }
        sum / norm
    }
}

#[cfg(test)]
mod tests;
