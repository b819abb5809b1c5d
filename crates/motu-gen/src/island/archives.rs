//! Archives: the meshes (plants, rocks, trunks) elements instance.

use super::*;

/// Archive detail by scale: 1, 2 or 3.
pub(super) fn detail(scale: f64) -> u32 {
    if scale < 0.01 {
        1
    } else if scale < 0.1 {
        2
    } else {
        3
    }
}

pub(super) fn tube(
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

pub(super) fn archive_mesh(kind: ArchiveKind, seed: u64, m: u32) -> Mesh {
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
pub(super) struct TrunkSpec {
    pub(super) height: f64,
    pub(super) palm: bool,
    pub(super) sections: u32,
    pub(super) segments: u32,
    pub(super) rows_per_section: u32,
    pub(super) branches: u32,
    pub(super) branch_segments: u32,
    pub(super) branch_rows: u32,
}

impl TrunkSpec {
    pub(super) fn new(
        height: f64,
        palm: bool,
        ply_tris: f64,
        inline_tris: f64,
        max_tris: u32,
    ) -> Self {
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

    pub(super) fn section(&self, index: u32) -> impl TriangleSource {
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

    pub(super) fn branch(&self, index: u32) -> impl TriangleSource {
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

    pub(super) fn ply_triangles(&self) -> u64 {
        u64::from(self.section(0).triangle_count()) * u64::from(self.sections)
    }

    pub(super) fn inline_triangles(&self) -> u64 {
        if self.branches == 0 {
            0
        } else {
            u64::from(self.branch(0).triangle_count()) * u64::from(self.branches)
        }
    }
}

pub(super) enum ArchiveBody {
    Mesh(Mesh),
    /// The trunk; PLY sections are separate files.
    Trunk {
        spec: TrunkSpec,
        ply_files: Vec<String>,
    },
}

pub(super) struct Archive {
    pub(super) object: String,
    pub(super) file: String,
    pub(super) material: &'static str,
    pub(super) body: ArchiveBody,
    pub(super) triangles: u64,
}
