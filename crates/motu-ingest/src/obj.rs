//! OBJ (+ MTL base colours) through tobj.

use crate::{IngestError, IngestReport};
use motu_scene::{GeometryStore, Material, MeshData, Scene, SceneBuilder};
use std::io::BufRead;
use std::path::{Path, PathBuf};

/// A material library bigger than this is not one (the bound keeps a device or a huge file
/// from being read as one endless line).
const MTL_MAX_BYTES: u64 = 256 << 20;

/// Imports an OBJ file. A referenced `.mtl` that is missing is an error unless
/// `allow_missing` (then a warning and default materials).
pub fn ingest_obj(
    path: &Path,
    allow_missing: bool,
    geometry: Box<dyn GeometryStore>,
) -> Result<(Scene, IngestReport), IngestError> {
    let shown = path.display().to_string();
    if let Some((line, col, detail)) = scan_obj(path, Scan::FaceIndices) {
        return Err(IngestError::Obj {
            path: format!("{shown}:{line}:{col}"),
            reason: if detail.starts_with("index ") {
                format!("face index out of bounds: {detail}")
            } else {
                detail
            },
        });
    }
    let mut report = IngestReport {
        files: 1,
        ..Default::default()
    };
    report.input_files.push(path.to_path_buf());
    // Material libraries are checked before tobj opens them: a FIFO would block it and
    // `/dev/zero` would be read as one endless line.
    for (line, lib) in mtllibs(path) {
        match pbrt_import::check_input(&lib, Some(MTL_MAX_BYTES)) {
            Ok(_) => {
                // tobj names neither the library nor the line of what it cannot read.
                if let Some((mline, detail)) = scan_mtl(&lib) {
                    return Err(IngestError::Obj {
                        path: format!("{}:{mline}", lib.display()),
                        reason: format!("{detail} (material library of {shown}:{line})"),
                    });
                }
                report.input_files.push(lib)
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound && allow_missing => {
                report.warnings.push(format!(
                    "{shown}:{line}: missing file {} (materials skipped)",
                    lib.display()
                ));
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err(IngestError::Obj {
                    path: format!("{shown}:{line}"),
                    reason: format!(
                        "mtllib {}: missing file (import with --allow-missing to use default materials)",
                        lib.display()
                    ),
                });
            }
            Err(source) => {
                return Err(IngestError::MtlUnreadable {
                    path: format!("{shown}:{line}"),
                    lib,
                    source,
                });
            }
        }
    }
    let (models, materials) = tobj::load_obj(
        path,
        &tobj::LoadOptions {
            triangulate: true,
            single_index: true,
            ..Default::default()
        },
    )
    .map_err(|e| match scan_obj(path, Scan::After(e)) {
        Some((line, col, detail)) => IngestError::ObjLoad {
            path: format!("{shown}:{line}:{col}"),
            detail: Some(detail),
            source: e,
        },
        None => IngestError::ObjLoad {
            path: shown.clone(),
            detail: None,
            source: e,
        },
    })?;
    let mut b = SceneBuilder::new(geometry);
    let mut mat_ids = Vec::new();
    let dir = path.parent().unwrap_or(Path::new("."));
    let mut mat_names: Vec<String> = Vec::new();
    match materials {
        Ok(ms) => {
            mat_names = ms.iter().map(|m| m.name.clone()).collect();
            for m in ms {
                // MTL map names are relative to the OBJ; a missing file falls back to Kd.
                let mut texture = |name: &Option<String>, is_alpha: bool| {
                    let name = name.as_ref()?;
                    let file = dir.join(name);
                    if let Err(e) = pbrt_import::check_input(&file, None) {
                        let why = if e.kind() == std::io::ErrorKind::NotFound {
                            "texture file missing".to_string()
                        } else {
                            e.to_string()
                        };
                        report.warnings.push(format!(
                            "{shown}: {why}: {}; the material's constant colour is used",
                            file.display()
                        ));
                        return None;
                    }
                    Some(b.add_texture(motu_scene::Texture {
                        path: file,
                        is_alpha,
                        ptex: false,
                    }))
                };
                let base_color_texture = texture(&m.diffuse_texture, false);
                let alpha_texture = texture(&m.dissolve_texture, true);
                // Phong exponent to roughness (Ns 0 → 1, Ns 1000 → ~0.06).
                let roughness = m
                    .shininess
                    .map_or(1.0, |ns| (2.0 / (ns.max(0.0) + 2.0)).sqrt().clamp(0.0, 1.0));
                let id = b
                    .add_material(Material {
                        name: m.name.clone(),
                        base_color: m.diffuse.unwrap_or([0.5; 3]),
                        opacity: m.dissolve.unwrap_or(1.0),
                        alpha_texture,
                        base_color_texture,
                        roughness,
                        ..Material::default()
                    })
                    .map_err(|e| IngestError::Scene {
                        at: shown.clone(),
                        source: e,
                    })?;
                mat_ids.push(id);
            }
        }
        // Missing libraries were handled above (error, or a warning with --allow-missing).
        Err(tobj::LoadError::OpenFileFailed) if allow_missing => {}
        Err(source) => {
            let libs: Vec<String> = mtllibs(path)
                .iter()
                .map(|(line, lib)| format!("{} (line {line})", lib.display()))
                .collect();
            return Err(IngestError::Materials {
                path: shown.clone(),
                libs: libs.join(", "),
                source,
            });
        }
    }
    // `usemtl` of a material no library defines: tobj drops it silently (default material).
    let defined: std::collections::HashSet<&str> = mat_names.iter().map(String::as_str).collect();
    let mut undefined = 0u64;
    let mut first_undefined = None;
    for (i, l) in obj_lines(path).into_iter().flatten().enumerate() {
        let mut words = l.split_whitespace();
        if words.next() == Some("usemtl") {
            let name = words.collect::<Vec<_>>().join(" ");
            if !defined.contains(name.as_str()) {
                undefined += 1;
                first_undefined.get_or_insert((i + 1, name));
            }
        }
    }
    if let Some((line, name)) = first_undefined {
        report.warnings.push(format!(
            "{shown}:{line}: usemtl \"{name}\" names no material of the file's libraries; {undefined} such usemtl line(s) use the default material"
        ));
    }
    let scene_err = |e| IngestError::Scene {
        at: shown.clone(),
        source: e,
    };
    for model in models {
        let m = &model.mesh;
        report.shapes += 1;
        let positions: Vec<[f32; 3]> = m
            .positions
            .chunks_exact(3)
            .map(|p| [p[0], p[1], p[2]])
            .collect();
        let normals = (m.normals.len() == m.positions.len()).then(|| {
            m.normals
                .chunks_exact(3)
                .map(|n| [n[0], n[1], n[2]])
                .collect()
        });
        let uvs = (m.texcoords.len() / 2 == positions.len() && !m.texcoords.is_empty())
            .then(|| m.texcoords.chunks_exact(2).map(|t| [t[0], t[1]]).collect());
        let data = MeshData {
            positions,
            normals,
            uvs,
            indices: m.indices.clone(),
        };
        if data.indices.is_empty() {
            report.degenerate_meshes += 1;
            continue;
        }
        let mat = m
            .material_id
            .and_then(|i| mat_ids.get(i).copied())
            .unwrap_or(b.default_material());
        b.add_mesh_owned(b.root(), &model.name, mat, Scene::MAIN_ELEMENT, data)
            .map_err(scene_err)?;
        report.meshes += 1;
    }
    Ok((b.finish().map_err(scene_err)?, report))
}

/// Each `mtllib` of the OBJ: (1-based line, the library's path beside the OBJ).
fn mtllibs(path: &Path) -> Vec<(usize, PathBuf)> {
    let dir = path.parent().unwrap_or(Path::new(""));
    let Ok(f) = std::fs::File::open(path) else {
        return Vec::new();
    };
    std::io::BufReader::new(f)
        .lines()
        .map_while(Result::ok)
        .enumerate()
        .filter_map(|(i, l)| {
            // As tobj reads it: the first whitespace-separated word is the keyword (a form
            // feed separates it too), the name is what follows the line's first space.
            if l.split_whitespace().next() != Some("mtllib") {
                return None;
            }
            let rest = l.split_once(' ').map_or("", |(_, r)| r).trim();
            (!rest.is_empty()).then(|| (i + 1, dir.join(rest)))
        })
        .collect()
}

/// The first line of a material library tobj would misread or turn into non-finite values:
/// binary data (not UTF-8, NUL bytes), or a colour or number that does not parse or is not
/// finite. (1-based line, what is wrong).
fn scan_mtl(path: &Path) -> Option<(usize, String)> {
    let f = std::fs::File::open(path).ok()?;
    for (i, raw) in std::io::BufReader::new(f)
        .split(b'\n')
        .map_while(Result::ok)
        .enumerate()
    {
        let Ok(line) = std::str::from_utf8(&raw) else {
            return Some((i + 1, "binary data, not a text material library".into()));
        };
        if line.contains('\0') {
            return Some((i + 1, "binary data, not a text material library".into()));
        }
        let mut words = line.split_whitespace();
        let Some(kw) = words.next() else { continue };
        if !matches!(
            kw,
            "Ka" | "Kd" | "Ks" | "Ke" | "Kt" | "Tf" | "Ns" | "Ni" | "d" | "Tr" | "illum"
        ) {
            continue;
        }
        let words: Vec<&str> = words.collect();
        // tobj reads a colour as its first three words and panics (an unwrap) when fewer than
        // three are there and all parse: `Kd`, `Kd 1`, `Kd 1 1`.
        if matches!(kw, "Ka" | "Kd" | "Ks" | "Ke")
            && words.len() < 3
            && words.iter().all(|w| w.parse::<f32>().is_ok())
        {
            return Some((
                i + 1,
                format!("`{kw}` needs three numbers, has {}", words.len()),
            ));
        }
        for w in words {
            match w.parse::<f32>() {
                Ok(v) if v.is_finite() => {}
                Ok(v) => {
                    return Some((
                        i + 1,
                        format!("`{kw}` value {w} is {v}, not a finite number"),
                    ))
                }
                // `Kd spectral file.rfl`, `Kd xyz 1 1 1`: words tobj skips.
                Err(_) if w.chars().next().is_some_and(|c| c.is_ascii_alphabetic()) => {}
                Err(_) => return Some((i + 1, format!("`{kw}`: `{w}` is not a number"))),
            }
        }
    }
    None
}

/// What [`scan_obj`] looks for.
#[derive(Clone, Copy, PartialEq)]
enum Scan {
    /// The line tobj failed on (tobj reports no position).
    After(tobj::LoadError),
    /// Face references tobj would resolve outside their arrays: tobj 4 overflows (a panic in
    /// checked builds, a wrapped index otherwise) on relative or huge texture-coordinate and
    /// normal indices, so they are refused before tobj sees the file.
    FaceIndices,
}

/// Lines of an OBJ, streamed (never the whole file in memory), non-UTF-8 bytes replaced.
fn obj_lines(path: &Path) -> Option<impl Iterator<Item = String>> {
    let f = std::fs::File::open(path).ok()?;
    Some(
        std::io::BufReader::new(f)
            .split(b'\n')
            .map_while(Result::ok)
            .map(|l| {
                String::from_utf8_lossy(&l)
                    .trim_end_matches('\r')
                    .to_string()
            }),
    )
}

/// Finds the first line with the problem `scan` asks for: (line, column, what is wrong).
fn scan_obj(path: &Path, scan: Scan) -> Option<(usize, usize, String)> {
    use tobj::LoadError as E;
    let is = |e: E| scan == Scan::After(e);
    // Totals first: face indices are checked against the whole file's counts (tobj's rule),
    // relative (negative) ones against the count so far.
    let mut totals = [0usize; 3];
    for line in obj_lines(path)? {
        match line.split_whitespace().next() {
            Some("v") => totals[0] += 1,
            Some("vt") => totals[1] += 1,
            Some("vn") => totals[2] += 1,
            _ => {}
        }
    }
    let mut seen = [0usize; 3];
    let col_of = |line: &str, tok: &str| line.find(tok).map_or(1, |c| c + 1);
    for (i, line) in obj_lines(path)?.enumerate() {
        let mut words = line.split_whitespace();
        let Some(kw) = words.next() else { continue };
        let args: Vec<&str> = words.collect();
        let floats_ok =
            |n: usize| args.len() >= n && args.iter().take(n).all(|a| a.parse::<f32>().is_ok());
        // NaN and values past f32 (`1e400`) would reach the scene as non-finite positions.
        if scan == Scan::FaceIndices && matches!(kw, "v" | "vt" | "vn") {
            if let Some(a) = args
                .iter()
                .find(|a| a.parse::<f32>().is_ok_and(|v| !v.is_finite()))
            {
                return Some((
                    i + 1,
                    col_of(line.as_str(), a),
                    format!("`{a}` is not a finite number (in `{line}`)"),
                ));
            }
        }
        match kw {
            "v" => {
                seen[0] += 1;
                if is(E::PositionParseError) && !floats_ok(3) {
                    return Some((i + 1, 1, format!("`{line}` needs 3 numbers")));
                }
            }
            "vt" => {
                seen[1] += 1;
                if is(E::TexcoordParseError) && !floats_ok(1) {
                    return Some((i + 1, 1, format!("`{line}` needs numbers")));
                }
            }
            "vn" => {
                seen[2] += 1;
                if is(E::NormalParseError) && !floats_ok(3) {
                    return Some((i + 1, 1, format!("`{line}` needs 3 numbers")));
                }
            }
            // tobj parses polylines (`l`) as faces: their references are resolved alike.
            "f" | "l" => {
                // tobj would turn a face of 1 or 2 vertices into a degenerate triangle.
                let few = scan == Scan::FaceIndices || is(E::InvalidPolygon);
                if kw == "f" && few && args.len() < 3 {
                    return Some((
                        i + 1,
                        1,
                        format!(
                            "a face needs at least 3 vertices, this one has {}",
                            args.len()
                        ),
                    ));
                }
                for a in &args {
                    for (k, part) in a.split('/').enumerate().take(3) {
                        if part.is_empty() {
                            continue;
                        }
                        let Ok(v) = part.parse::<i64>() else {
                            if is(E::FaceParseError) {
                                return Some((
                                    i + 1,
                                    col_of(line.as_str(), a),
                                    format!("`{a}` is not a vertex reference"),
                                ));
                            }
                            continue;
                        };
                        let (count, what, err) = match k {
                            0 => (totals[0], "positions", E::FaceVertexOutOfBounds),
                            1 => (totals[1], "texture coordinates", E::FaceTexCoordOutOfBounds),
                            _ => (totals[2], "normals", E::FaceNormalOutOfBounds),
                        };
                        let resolved = if v < 0 {
                            (seen[k] as i64).saturating_add(v).saturating_add(1)
                        } else {
                            v
                        };
                        let bad = v == 0 || resolved < 1 || resolved > count as i64;
                        // tobj ignores texture and normal references when the file has none.
                        let wanted = match scan {
                            Scan::After(e) => e == err,
                            Scan::FaceIndices => k == 0 || count > 0,
                        };
                        if bad && wanted {
                            return Some((
                                i + 1,
                                col_of(line.as_str(), a),
                                format!("index {v} in `{a}` is outside the file's {count} {what}"),
                            ));
                        }
                    }
                }
            }
            _ => {}
        }
    }
    None
}

#[cfg(test)]
mod tests;
