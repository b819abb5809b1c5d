//! The island in the layout of Moana's JSON+OBJ base package (`--format json`): the same
//! meshes, placements, materials, cameras and sun as the pbrt island, so importing either gives
//! the same scene (`tests/tests/moana_json.rs` compares them per pixel).
//!
//! ```text
//! json/island.json                       {"elements": [...], "cameras": [...], "lights": [...]}
//! json/<el>/<el>.json                    name, matFile, geomObjFile (terrain, if any),
//!                                        transformMatrix (identity), instancedPrimitiveJsonFiles
//! json/<el>/materials.json               the island's materials (baseColor, roughness, metallic)
//! json/<el>/<el>_<list>.json             archive OBJ → instance name → 16 numbers
//! json/cameras/<cam>.json                eye, look, up, fov (horizontal), ratio, resolution
//! json/lights/sun.json                   the sun (motu's `distant` light type)
//! obj/<el>/<el>.obj                      terrain patches, one group each (inline files' first)
//! obj/<el>/archives/<object>.obj         an archive: one group per mesh (trunk: sections first)
//! ```
//!
//! Numbers are written as the pbrt island writes them (the same decimals; PLY-stored vertices
//! as the shortest text of their f32), so both parse to the same bits. Events reach the
//! importer in the pbrt island's document order (archives, terrain, placements), so mesh ids
//! match a sequential pbrt import (`--threads 1`: parallel PLY loading reorders the pbrt side).

use std::io::Write;

use super::*;
use crate::pbrt::{push_transform_values, push_vec};
use crate::text::{push_fixed, push_u64};

/// Vertices of PLY-stored meshes: the shortest text that parses back to their f32.
const AS_F32: Option<u32> = None;

fn json_str(s: &str) -> String {
    // Names and paths here are plain ASCII identifiers; quote what JSON requires anyway.
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if (c as u32) < 0x20 => out.push_str(&format!("\\u{:04x}", c as u32)),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

fn push_json_vec(line: &mut Vec<u8>, v: Vec3, decimals: u32) {
    line.push(b'[');
    let start = line.len();
    push_vec(line, v, decimals);
    for b in &mut line[start..] {
        if *b == b' ' {
            *b = b',';
        }
    }
    line.push(b']');
}

/// One OBJ group: `g`, `usemtl`, its vertices and its faces (1-based, after `first_vertex`).
fn write_group(
    out: &mut OutFile<'_>,
    line: &mut Vec<u8>,
    group: &str,
    material: &str,
    mesh: &dyn TriangleSource,
    decimals: Option<u32>,
    first_vertex: &mut u64,
) -> Result<(), GenError> {
    line.clear();
    line.extend_from_slice(format!("g {group}\nusemtl {material}\n").as_bytes());
    for v in 0..mesh.vertex_count() {
        let p = mesh.vertex(v);
        line.push(b'v');
        for c in p {
            line.push(b' ');
            match decimals {
                Some(d) => push_fixed(line, c, d),
                None => {
                    let _ = write!(line, "{}", c as f32);
                }
            }
        }
        line.push(b'\n');
        if line.len() >= 60_000 {
            out.drain(line)?;
        }
    }
    for t in 0..mesh.triangle_count() {
        line.push(b'f');
        for i in mesh.triangle(t) {
            line.push(b' ');
            push_u64(line, *first_vertex + u64::from(i) + 1);
        }
        line.push(b'\n');
        if line.len() >= 60_000 {
            out.drain(line)?;
        }
    }
    out.drain(line)?;
    *first_vertex += u64::from(mesh.vertex_count());
    Ok(())
}

fn archive_obj(e: &ElementPlan, a: &Archive) -> String {
    format!("obj/{}/archives/{}.obj", e.name, a.object)
}

fn list_key(list: &PlacementList) -> &'static str {
    match &list.kind {
        ListKind::Scatter { kind, .. } => kind.list_name(),
        ListKind::PlantCopies { .. } => "xgCopies",
        ListKind::PlantLeaves { .. } => "xgLeaves",
    }
}

fn list_archives(list: &PlacementList) -> Range<usize> {
    match &list.kind {
        ListKind::Scatter { archives, .. } | ListKind::PlantLeaves { archives, .. } => {
            archives.clone()
        }
        ListKind::PlantCopies { trunk } => *trunk..*trunk + 1,
    }
}

fn list_file(e: &ElementPlan, li: usize) -> String {
    format!("json/{0}/{0}_{1}_{li}.json", e.name, list_key(&e.lists[li]))
}

fn has_terrain(e: &ElementPlan) -> bool {
    !e.inline_files.is_empty() || !e.ply_patches.is_empty()
}

fn write_element(ctx: &Ctx<'_>, e: &ElementPlan) -> Result<Tally, GenError> {
    let mut out = OutFile::create(ctx.root, &format!("json/{0}/{0}.json", e.name), ctx.live)?;
    let mut s = format!(
        "{{\n  \"name\": {},\n  \"matFile\": {},\n",
        json_str(e.name),
        json_str(&format!("json/{}/materials.json", e.name))
    );
    if has_terrain(e) {
        s += &format!(
            "  \"geomObjFile\": {},\n",
            json_str(&format!("obj/{0}/{0}.obj", e.name))
        );
    }
    s += "  \"transformMatrix\": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1],\n";
    s += "  \"instancedPrimitiveJsonFiles\": {";
    for (li, list) in e.lists.iter().enumerate() {
        let archives: Vec<String> = list_archives(list)
            .map(|a| json_str(&archive_obj(e, &e.archives[a])))
            .collect();
        s += &format!(
            "{}\n    {}: {{\"type\": \"archive\", \"jsonFile\": {}, \"archives\": [{}]}}",
            if li > 0 { "," } else { "" },
            json_str(&format!("{}_{li}", list_key(list))),
            json_str(&list_file(e, li)),
            archives.join(", ")
        );
    }
    s += "\n  }\n}\n";
    out.write_str(&s)?;
    let mut bytes = out.finish()?;
    // The materials: the island's table (a pbrt-v3 `matte` is rough and not metallic).
    let mut out = OutFile::create(
        ctx.root,
        &format!("json/{}/materials.json", e.name),
        ctx.live,
    )?;
    let mut line = b"{".to_vec();
    for (i, (name, rgb)) in MATERIALS.iter().enumerate() {
        if i > 0 {
            line.push(b',');
        }
        line.extend_from_slice(format!("\n  {}: {{\"baseColor\": ", json_str(name)).as_bytes());
        push_json_vec(&mut line, *rgb, 4);
        line.extend_from_slice(b", \"roughness\": 1, \"metallic\": 0}");
    }
    line.extend_from_slice(b"\n}\n");
    out.drain(&mut line)?;
    bytes += out.finish()?;
    Ok(Tally {
        files: 2,
        ..Tally::file(bytes)
    })
}

fn write_archive(ctx: &Ctx<'_>, e: &ElementPlan, a: &Archive) -> Result<Tally, GenError> {
    let mut out = OutFile::create(ctx.root, &archive_obj(e, a), ctx.live)?;
    let mut line = Vec::with_capacity(1 << 16);
    let mut first = 0u64;
    let unique = match &a.body {
        ArchiveBody::Mesh(mesh) => {
            write_group(
                &mut out,
                &mut line,
                &a.object,
                a.material,
                mesh,
                Some(4),
                &mut first,
            )?;
            a.triangles
        }
        ArchiveBody::Trunk { spec, .. } => {
            let mut triangles = 0;
            for s in 0..spec.sections {
                let section = spec.section(s);
                triangles += u64::from(section.triangle_count());
                let group = format!("{}_section_{s:05}", a.object);
                write_group(
                    &mut out, &mut line, &group, a.material, &section, AS_F32, &mut first,
                )?;
            }
            for b in 0..spec.branches {
                let group = format!("{}_branch_{b:03}", a.object);
                write_group(
                    &mut out,
                    &mut line,
                    &group,
                    a.material,
                    &spec.branch(b),
                    Some(4),
                    &mut first,
                )?;
            }
            triangles + spec.inline_triangles()
        }
    };
    Ok(Tally {
        unique_triangles: unique,
        ..Tally::file(out.finish()?)
    })
}

fn write_terrain(ctx: &Ctx<'_>, terrain: &Terrain, e: &ElementPlan) -> Result<Tally, GenError> {
    let mut out = OutFile::create(ctx.root, &format!("obj/{0}/{0}.obj", e.name), ctx.live)?;
    let mut line = Vec::with_capacity(1 << 16);
    let mut first = 0u64;
    let mut triangles = 0u64;
    let mut n = 0usize;
    for (_, patches) in &e.inline_files {
        for p in patches {
            let group = format!("{}_patch_{n:05}", e.name);
            write_group(
                &mut out,
                &mut line,
                &group,
                e.material,
                &p.source(terrain),
                Some(POSITION_DECIMALS),
                &mut first,
            )?;
            triangles += p.triangles();
            n += 1;
        }
    }
    for (_, p) in &e.ply_patches {
        let group = format!("{}_patch_{n:05}", e.name);
        write_group(
            &mut out,
            &mut line,
            &group,
            e.material,
            &p.source(terrain),
            AS_F32,
            &mut first,
        )?;
        triangles += p.triangles();
        n += 1;
    }
    Ok(Tally {
        unique_triangles: triangles,
        instanced_triangles: triangles,
        ..Tally::file(out.finish()?)
    })
}

/// A placement list's archive JSON: grouped by archive, so the list is walked once per archive
/// (a few variants) instead of holding it.
fn write_list(
    o: &IslandOptions,
    ctx: &Ctx<'_>,
    terrain: &Terrain,
    e: &ElementPlan,
    li: usize,
) -> Result<Tally, GenError> {
    let list = &e.lists[li];
    let total = list.files.last().map_or(0, |(_, r)| r.end);
    let mut out = OutFile::create(ctx.root, &list_file(e, li), ctx.live)?;
    let mut line = Vec::with_capacity(1 << 16);
    line.push(b'{');
    let mut instanced = 0u64;
    for (ai, archive) in list_archives(list).enumerate() {
        let a = &e.archives[archive];
        if ai > 0 {
            line.push(b',');
        }
        line.extend_from_slice(format!("\n  {}: {{", json_str(&archive_obj(e, a))).as_bytes());
        let mut first = true;
        let mut cached = None;
        for k in 0..total {
            let (m, pick) = writers::placement(o, terrain, e, li, k, &mut cached);
            if pick != archive {
                continue;
            }
            if !first {
                line.push(b',');
            }
            first = false;
            line.extend_from_slice(format!("\n    \"{}_{k}\": [", a.object).as_bytes());
            let start = line.len();
            push_transform_values(&mut line, &m, POSITION_DECIMALS);
            for b in &mut line[start..] {
                if *b == b' ' {
                    *b = b',';
                }
            }
            line.push(b']');
            instanced += a.triangles;
            if line.len() >= 60_000 {
                out.drain(&mut line)?;
            }
        }
        line.extend_from_slice(b"\n  }");
    }
    line.extend_from_slice(b"\n}\n");
    out.drain(&mut line)?;
    Ok(Tally {
        object_instances: total,
        flattened_instances: total,
        instanced_triangles: instanced,
        ..Tally::file(out.finish()?)
    })
}

fn write_camera(
    ctx: &Ctx<'_>,
    o: &IslandOptions,
    name: &str,
    spec: &CameraSpec,
) -> Result<Tally, GenError> {
    let mut out = OutFile::create(ctx.root, &format!("json/cameras/{name}.json"), ctx.live)?;
    // pbrt's fov (as written, 4 decimals) spans the shorter side; the release's the width.
    let fov_short = (spec.fov_deg * 1e4).round() / 1e4;
    let ratio = f64::from(o.width) / f64::from(o.height);
    let fov = if ratio > 1.0 {
        2.0 * ((fov_short.to_radians() * 0.5).tan() * ratio)
            .atan()
            .to_degrees()
    } else {
        fov_short
    };
    let mut line = format!("{{\n  \"name\": {},\n  \"eye\": ", json_str(name)).into_bytes();
    push_json_vec(&mut line, spec.eye, 4);
    line.extend_from_slice(b",\n  \"look\": ");
    push_json_vec(&mut line, spec.target, 4);
    line.extend_from_slice(
        format!(
            ",\n  \"up\": [0, 1, 0],\n  \"fov\": {fov:?},\n  \"ratio\": {ratio:?},\n  \"resolution\": [{}, {}],\n  \"handedness\": \"left\"\n}}\n",
            o.width, o.height
        )
        .as_bytes(),
    );
    out.drain(&mut line)?;
    Ok(Tally::file(out.finish()?))
}

fn write_scene_list(ctx: &Ctx<'_>, elements: &[ElementPlan]) -> Result<Tally, GenError> {
    let mut out = OutFile::create(ctx.root, "json/island.json", ctx.live)?;
    let list = |items: Vec<String>| {
        items
            .iter()
            .map(|s| format!("\n    {}", json_str(s)))
            .collect::<Vec<_>>()
            .join(",")
    };
    let s = format!(
        "{{\n  \"elements\": [{}\n  ],\n  \"cameras\": [{}\n  ],\n  \"lights\": [\"json/lights/sun.json\"]\n}}\n",
        list(elements.iter().map(|e| format!("json/{0}/{0}.json", e.name)).collect()),
        list(ISLAND_CAMERAS.iter().map(|c| format!("json/cameras/{c}.json")).collect()),
    );
    out.write_str(&s)?;
    let mut bytes = out.finish()?;
    let mut out = OutFile::create(ctx.root, "json/lights/sun.json", ctx.live)?;
    let mut line = b"{\"sun\": {\"type\": \"distant\", \"from\": ".to_vec();
    push_json_vec(&mut line, SUN_FROM, 4);
    line.extend_from_slice(b", \"to\": [0, 0, 0], \"color\": ");
    push_json_vec(&mut line, SUN_RADIANCE, 4);
    line.extend_from_slice(b"}}\n");
    out.drain(&mut line)?;
    bytes += out.finish()?;
    Ok(Tally {
        files: 2,
        ..Tally::file(bytes)
    })
}

pub(super) fn generate(
    o: &IslandOptions,
    root: &Path,
    progress: &mut dyn FnMut(GenProgress),
) -> Result<GenSummary, GenError> {
    if o.terrain_objects {
        return Err(GenError::InvalidOption {
            option: "terrain-objects",
            reason:
                "applies to the pbrt island only (the base package places terrain in its element)"
                    .into(),
        });
    }
    let terrain = Terrain::new(o.seed);
    let elements = plan(o);
    let cams = cameras(&terrain);
    let (t, els) = (&terrain, &elements);
    let mut jobs: Vec<Job<'_>> = Vec::new();
    for e in els {
        for li in 0..e.lists.len() {
            jobs.push(Box::new(move |ctx: &Ctx<'_>| write_list(o, ctx, t, e, li)));
        }
        if has_terrain(e) {
            jobs.push(Box::new(move |ctx: &Ctx<'_>| write_terrain(ctx, t, e)));
        }
        for a in &e.archives {
            jobs.push(Box::new(move |ctx: &Ctx<'_>| write_archive(ctx, e, a)));
        }
        jobs.push(Box::new(move |ctx: &Ctx<'_>| write_element(ctx, e)));
    }
    for (name, spec) in &cams {
        jobs.push(Box::new(move |ctx: &Ctx<'_>| {
            write_camera(ctx, o, name, spec)
        }));
    }
    jobs.push(Box::new(move |ctx: &Ctx<'_>| write_scene_list(ctx, els)));
    let tally = run_jobs(root, jobs, o.threads, progress)?;
    Ok(GenSummary {
        scene_path: root.join("json/island.json"),
        files_written: tally.files,
        bytes_written: tally.bytes,
        object_instances: tally.object_instances,
        flattened_instances: tally.flattened_instances,
        unique_triangles: tally.unique_triangles,
        instanced_triangles: tally.instanced_triangles,
        elements: elements.iter().map(|e| e.name.to_string()).collect(),
        cameras: ISLAND_CAMERAS.iter().map(|c| c.to_string()).collect(),
        nested_instancing: false,
        syntax: None,
    })
}
