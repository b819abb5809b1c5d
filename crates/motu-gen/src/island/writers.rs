//! Writers: the scene, camera, element, archive, inline-geometry and placement files.

use super::*;

pub(super) fn cameras(terrain: &Terrain) -> Vec<(&'static str, CameraSpec)> {
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

pub(super) fn write_scene_file(
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
    push_sun(&mut line, syntax, SUN_FROM, SUN_RADIANCE);
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

pub(super) fn write_camera_file(
    ctx: &Ctx<'_>,
    name: &str,
    spec: &CameraSpec,
) -> Result<Tally, GenError> {
    let mut out = OutFile::create(ctx.root, &format!("cameras/{name}.pbrt"), ctx.live)?;
    // Identity: several camera files are included in a row, and LookAt composes.
    let mut line = format!("# {name}\nIdentity\n").into_bytes();
    push_camera(&mut line, spec);
    out.drain(&mut line)?;
    Ok(Tally::file(out.finish()?))
}

pub(super) fn write_element_file(
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

pub(super) fn write_archive_file(ctx: &Ctx<'_>, a: &Archive) -> Result<Tally, GenError> {
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

pub(super) fn write_inline_file(
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

pub(super) fn write_placements(
    o: &IslandOptions,
    ctx: &Ctx<'_>,
    terrain: &Terrain,
    e: &ElementPlan,
    list_index: usize,
    file: &str,
    range: Range<u64>,
) -> Result<Tally, GenError> {
    let mut out = OutFile::create(ctx.root, file, ctx.live)?;
    let mut line = Vec::with_capacity(1 << 16);
    let mut instanced = 0u64;
    let mut cached_copy: Option<(u64, Affine)> = None;
    for k in range.clone() {
        let (m, archive) = placement(o, terrain, e, list_index, k, &mut cached_copy);
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

/// Instance `k` of list `list_index`: its transform and archive (`cached_copy` keeps the last
/// plant copy's transform, which consecutive leaves share).
pub(super) fn placement(
    o: &IslandOptions,
    terrain: &Terrain,
    e: &ElementPlan,
    list_index: usize,
    k: u64,
    cached_copy: &mut Option<(u64, Affine)>,
) -> (Affine, usize) {
    let (height, palm, _) = e.plant.unwrap_or((1.0, false, 0));
    match &e.lists[list_index].kind {
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
            let world_from_plant = match *cached_copy {
                Some((c, m)) if c == copy => m,
                _ => {
                    let m = plant_transform(o, terrain, e.index, copy);
                    *cached_copy = Some((copy, m));
                    m
                }
            };
            let plant_from_leaf = leaf_transform(o, e.index, leaf, height, palm);
            let pick = archives.start + (leaf % archives.len().max(1) as u64) as usize;
            (world_from_plant.mul(&plant_from_leaf), pick)
        }
    }
}
