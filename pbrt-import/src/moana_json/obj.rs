//! The OBJ subset Moana's base package uses: `v`, `vn`, `vt`, `g`, `usemtl`, `f` (triangles,
//! quads and polygons, fan-split), 1-based or negative indices into file-wide vertex lists.
//!
//! Each `g`/`o` group (and each material change inside one) is one mesh, delivered as soon as it
//! ends, so only the file-wide vertex lists and one mesh are held. A group's corners usually
//! index one contiguous run of vertices with matching normal and uv runs (Moana's and
//! `motu gen`'s files): the mesh then keeps the file's vertex order; otherwise distinct corners
//! are numbered in order of first use.

use std::collections::HashMap;

use crate::events::Mesh;

/// One mesh of an OBJ file.
#[derive(Debug)]
pub(crate) struct ObjMesh {
    /// The group (`g`/`o`) name: in Moana, the stem of the mesh's Ptex file.
    pub group: String,
    /// The material (`usemtl`), empty when none was named.
    pub material: String,
    /// 1-based line of the group's first face.
    pub line: u32,
    pub mesh: Mesh,
}

#[derive(Debug)]
pub(crate) struct ObjError {
    pub line: u32,
    pub message: String,
}

#[derive(Default)]
struct Group {
    name: String,
    material: String,
    line: u32,
    /// Corners: (v, vt, vn) 0-based, `u32::MAX` when absent.
    corners: Vec<[u32; 3]>,
    /// Triangles as corner indices.
    triangles: Vec<u32>,
    /// Per triangle its Ptex face (`Mesh::face_ids`).
    face_ids: Vec<u32>,
    /// The group's next Ptex face id (continues across a `usemtl` inside the group).
    next_face: u32,
}

/// Reads `bytes` and calls `emit` with each mesh in file order.
pub(crate) fn read<E: From<ObjError>>(
    bytes: &[u8],
    mut emit: impl FnMut(ObjMesh) -> Result<(), E>,
) -> Result<(), E> {
    let mut v: Vec<[f32; 3]> = Vec::new();
    let mut vt: Vec<[f32; 2]> = Vec::new();
    let mut vn: Vec<[f32; 3]> = Vec::new();
    let mut group = Group::default();
    let mut corner_buf: Vec<[u32; 3]> = Vec::new();
    for (ln, raw) in bytes.split(|&b| b == b'\n').enumerate() {
        let line_no = (ln + 1) as u32;
        let err = |message: String| ObjError {
            line: line_no,
            message,
        };
        let line = trim(raw);
        if line.is_empty() || line[0] == b'#' {
            continue;
        }
        let (word, rest) = split_word(line);
        match word {
            b"v" => v.push(floats::<3>(rest).map_err(err)?),
            b"vn" => vn.push(floats::<3>(rest).map_err(err)?),
            b"vt" => {
                let t = floats_at_least::<2>(rest).map_err(err)?;
                vt.push(t);
            }
            b"g" | b"o" => {
                flush(&mut group, &v, &vt, &vn, &mut emit)?;
                group.name = String::from_utf8_lossy(trim(rest)).into_owned();
            }
            b"usemtl" => {
                let name = String::from_utf8_lossy(trim(rest)).into_owned();
                if name != group.material {
                    let keep = std::mem::take(&mut group.name);
                    let next_face = group.next_face;
                    flush(&mut group, &v, &vt, &vn, &mut emit)?;
                    group.name = keep;
                    group.next_face = next_face;
                    group.material = name;
                }
            }
            b"f" => {
                corner_buf.clear();
                for item in rest
                    .split(|b| b.is_ascii_whitespace())
                    .filter(|s| !s.is_empty())
                {
                    let mut parts = item.split(|&b| b == b'/');
                    let mut idx = [u32::MAX; 3];
                    let counts = [v.len(), vt.len(), vn.len()];
                    for (k, count) in counts.iter().enumerate() {
                        match parts.next() {
                            Some(p) if !p.is_empty() => {
                                idx[k] = index(p, *count).map_err(err)?;
                            }
                            _ if k == 0 => {
                                return Err(err(format!(
                                    "face corner `{}` has no vertex index",
                                    String::from_utf8_lossy(item)
                                ))
                                .into())
                            }
                            _ => {}
                        }
                    }
                    corner_buf.push(idx);
                }
                if corner_buf.len() < 3 {
                    return Err(err(format!(
                        "a face needs at least 3 corners, this one has {}",
                        corner_buf.len()
                    ))
                    .into());
                }
                if group.corners.is_empty() {
                    group.line = line_no;
                }
                let base = group.corners.len() as u32;
                group.corners.extend_from_slice(&corner_buf);
                for k in 1..corner_buf.len() as u32 - 1 {
                    group
                        .triangles
                        .extend_from_slice(&[base, base + k, base + k + 1]);
                }
                // Ptex faces: a triangle or a quad is one (a quad's second triangle its second
                // half); an n-gon has n sub-faces, its triangles sampled in the first.
                let face = group.next_face;
                let n = corner_buf.len() as u32;
                group.face_ids.push(face);
                let rest = if n == 4 {
                    face | crate::events::FACE_SECOND_HALF
                } else {
                    face
                };
                group
                    .face_ids
                    .extend(std::iter::repeat_n(rest, n as usize - 3));
                group.next_face = face.saturating_add(if n <= 4 { 1 } else { n });
            }
            // Smoothing groups, material libraries, lines and points carry nothing motu keeps.
            _ => {}
        }
    }
    flush(&mut group, &v, &vt, &vn, &mut emit)
}

fn flush<E>(
    g: &mut Group,
    v: &[[f32; 3]],
    vt: &[[f32; 2]],
    vn: &[[f32; 3]],
    emit: &mut impl FnMut(ObjMesh) -> Result<(), E>,
) -> Result<(), E> {
    let material = g.material.clone();
    let name = std::mem::take(&mut g.name);
    if g.triangles.is_empty() {
        *g = Group {
            material,
            ..Group::default()
        };
        return Ok(());
    }
    let has_uv = g.corners.iter().all(|c| c[1] != u32::MAX);
    let has_n = g.corners.iter().all(|c| c[2] != u32::MAX);
    // Contiguous runs with the same offsets: keep the file's vertex order.
    let lo = g.corners.iter().map(|c| c[0]).min().unwrap_or(0);
    let hi = g.corners.iter().map(|c| c[0]).max().unwrap_or(0);
    let same_offsets = |k: usize| -> Option<i64> {
        let d = i64::from(g.corners[0][k]) - i64::from(g.corners[0][0]);
        g.corners
            .iter()
            .all(|c| i64::from(c[k]) - i64::from(c[0]) == d)
            .then_some(d)
    };
    let run = |k: usize, len: usize| -> Option<i64> {
        let d = same_offsets(k)?;
        let (a, b) = (i64::from(lo) + d, i64::from(hi) + d);
        (a >= 0 && (b as usize) < len).then_some(d)
    };
    let uv_run = if has_uv { run(1, vt.len()) } else { Some(0) };
    let n_run = if has_n { run(2, vn.len()) } else { Some(0) };
    let mesh = match (uv_run, n_run) {
        (Some(du), Some(dn)) => {
            let range = lo as usize..=hi as usize;
            let shift = |d: i64| (i64::from(lo) + d) as usize..=(i64::from(hi) + d) as usize;
            Mesh {
                positions: v[range].to_vec(),
                uvs: has_uv.then(|| vt[shift(du)].to_vec()),
                normals: has_n.then(|| vn[shift(dn)].to_vec()),
                indices: g
                    .triangles
                    .iter()
                    .map(|&c| g.corners[c as usize][0] - lo)
                    .collect(),
                face_ids: None,
            }
        }
        _ => {
            let mut remap: HashMap<[u32; 3], u32> = HashMap::new();
            let mut m = Mesh {
                normals: has_n.then(Vec::new),
                uvs: has_uv.then(Vec::new),
                ..Mesh::default()
            };
            let mut corner_vertex = Vec::with_capacity(g.corners.len());
            for c in &g.corners {
                let next = remap.len() as u32;
                let id = *remap.entry(*c).or_insert_with(|| {
                    m.positions.push(v[c[0] as usize]);
                    if let Some(uvs) = &mut m.uvs {
                        uvs.push(vt[c[1] as usize]);
                    }
                    if let Some(ns) = &mut m.normals {
                        ns.push(vn[c[2] as usize]);
                    }
                    next
                });
                corner_vertex.push(id);
            }
            m.indices = g
                .triangles
                .iter()
                .map(|&c| corner_vertex[c as usize])
                .collect();
            m
        }
    };
    let mut mesh = mesh;
    mesh.face_ids = Some(std::mem::take(&mut g.face_ids));
    let out = ObjMesh {
        group: name,
        material: material.clone(),
        line: g.line,
        mesh,
    };
    *g = Group {
        material,
        ..Group::default()
    };
    emit(out)
}

fn trim(s: &[u8]) -> &[u8] {
    let start = s
        .iter()
        .position(|b| !b.is_ascii_whitespace())
        .unwrap_or(s.len());
    let end = s
        .iter()
        .rposition(|b| !b.is_ascii_whitespace())
        .map_or(start, |e| e + 1);
    &s[start..end.max(start)]
}

fn split_word(s: &[u8]) -> (&[u8], &[u8]) {
    match s.iter().position(u8::is_ascii_whitespace) {
        Some(i) => (&s[..i], &s[i..]),
        None => (s, &[]),
    }
}

fn floats_at_least<const N: usize>(rest: &[u8]) -> Result<[f32; N], String> {
    let mut out = [0.0f32; N];
    let mut n = 0;
    for w in rest
        .split(|b| b.is_ascii_whitespace())
        .filter(|s| !s.is_empty())
    {
        if n < N {
            out[n] = parse_f32(w)?;
        }
        n += 1;
    }
    if n < N {
        return Err(format!("expected {N} numbers, found {n}"));
    }
    Ok(out)
}

fn floats<const N: usize>(rest: &[u8]) -> Result<[f32; N], String> {
    // `v x y z [w]` and colour extensions `v x y z r g b`: the first three are the position.
    floats_at_least::<N>(rest)
}

fn parse_f32(w: &[u8]) -> Result<f32, String> {
    match fast_float2::parse::<f32, _>(w) {
        Ok(x) if x.is_finite() => Ok(x),
        Ok(_) => Err(format!(
            "`{}` is not a finite number",
            String::from_utf8_lossy(w)
        )),
        Err(_) => Err(format!("`{}` is not a number", String::from_utf8_lossy(w))),
    }
}

/// 1-based (or negative, relative to the end) OBJ index → 0-based, checked against `count`.
fn index(w: &[u8], count: usize) -> Result<u32, String> {
    // By hand: faces are most of an OBJ's bytes, and str::parse needs a UTF-8 check first.
    let (negative, digits) = match w.split_first() {
        Some((b'-', rest)) => (true, rest),
        _ => (false, w),
    };
    let bad = || format!("`{}` is not an index", String::from_utf8_lossy(w));
    if digits.is_empty() || digits.len() > 18 {
        return Err(bad());
    }
    let mut i: i64 = 0;
    for &d in digits {
        if !d.is_ascii_digit() {
            return Err(bad());
        }
        i = i * 10 + i64::from(d - b'0');
    }
    let i = if negative { -i } else { i };
    let zero_based = if i < 0 { count as i64 + i } else { i - 1 };
    if i == 0 || zero_based < 0 || zero_based >= count as i64 {
        return Err(format!(
            "index {i} is out of range ({count} defined so far)"
        ));
    }
    Ok(zero_based as u32)
}

#[cfg(test)]
mod tests;
