//! The island's catalogue: archive kinds, element roles, the 20 element definitions and the
//! materials.

use super::*;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum ArchiveKind {
    Rock,
    Shell,
    Grass,
    Flower,
    Coral,
    Leaf,
    Frond,
}

impl ArchiveKind {
    pub(super) fn name(self) -> &'static str {
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

    pub(super) fn list_name(self) -> &'static str {
        match self {
            ArchiveKind::Rock => "xgRocks",
            ArchiveKind::Shell => "xgShells",
            ArchiveKind::Grass => "xgGrass",
            ArchiveKind::Flower => "xgFlowers",
            ArchiveKind::Coral => "xgCoral",
            ArchiveKind::Leaf | ArchiveKind::Frond => "xgLeaves",
        }
    }

    pub(super) fn material(self) -> &'static str {
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
    pub(super) fn scale_range(self) -> (f64, f64) {
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
pub(super) enum Role {
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

pub(super) struct ElementDef {
    pub(super) name: &'static str,
    pub(super) role: Role,
    pub(super) instance_weight: f64,
    pub(super) inline_weight: f64,
    pub(super) ply_weight: f64,
}

pub(super) const fn def(
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

pub(super) const PLANT_SMALL: f64 = 0.01;
pub(super) static DEFS: [ElementDef; 20] = [
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
pub(super) const MATERIALS: [(&str, Vec3); 11] = [
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
