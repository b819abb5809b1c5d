//! The island's plan: per element its archives, geometry files and placement lists (split into
//! files), and the transforms of plants, leaves and scattered archives.

use super::*;

#[derive(Clone, Debug)]
pub(super) enum ListKind {
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

pub(super) struct PlacementList {
    pub(super) kind: ListKind,
    /// Per file: its path and the instance indices it holds.
    pub(super) files: Vec<(String, Range<u64>)>,
}

pub(super) struct ElementPlan {
    pub(super) index: u64,
    pub(super) name: &'static str,
    pub(super) material: &'static str,
    pub(super) archives: Vec<Archive>,
    pub(super) inline_files: Vec<(String, Vec<Patch>)>,
    pub(super) ply_patches: Vec<(String, Patch)>,
    /// (trunk archive index, section index, file)
    pub(super) trunk_sections: Vec<(usize, u32, String)>,
    pub(super) lists: Vec<PlacementList>,
    pub(super) plant: Option<(f64, bool, u64)>, // (height, palm, copies)
}

pub(super) fn element_count(o: &IslandOptions) -> u32 {
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

pub(super) fn split_files(
    prefix: &str,
    count: u64,
    max_per_file: u64,
) -> Vec<(String, Range<u64>)> {
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

pub(super) fn plan(o: &IslandOptions) -> Vec<ElementPlan> {
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

pub(super) fn plant_transform(
    o: &IslandOptions,
    terrain: &Terrain,
    element: u64,
    copy: u64,
) -> Affine {
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

pub(super) fn leaf_transform(
    o: &IslandOptions,
    element: u64,
    leaf: u64,
    height: f64,
    palm: bool,
) -> Affine {
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

pub(super) fn scatter_transform(
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
