//! PLY reader: ASCII and binary (little/big endian), `.ply.gz`, any property types.
//!
//! Faces (triangles, quads, polygons) are fan-triangulated; `tristrips` elements (strips
//! separated by -1) are unrolled. Faces of fewer than 3 vertices are dropped and counted
//! ([`PlyReport`]). Vertex normals come from `nx ny nz`; texture coordinates from any of
//! pbrt's names (`u v`, `s t`, `texture_u texture_v`, `texture_s texture_t`). `face_indices`
//! (pbrt's Ptex face per face) becomes [`Mesh::face_ids`]; other properties/elements are read
//! and skipped. ASCII bodies hold one element item
//! per line (the PLY rule): a missing or extra value is an error naming the line.

use std::path::Path;

mod body;
mod header;
mod write;

use crate::error::PlyError;
use crate::events::Mesh;
use crate::source::SourceBytes;
use body::{body_err, decode, Body};
use header::{parse_header, Element, Format, PropKind, Property, Scalar};
pub use write::write_ply_binary_le;

/// What a PLY file held that did not become triangles.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PlyReport {
    /// Faces with fewer than 3 vertices (dropped).
    pub dropped_faces: u64,
    /// Where the first one is: the face's index, and its line in an ASCII file.
    pub first_dropped: Option<(usize, Option<usize>)>,
}

impl PlyReport {
    /// A warning for the caller to show, `None` when nothing was dropped.
    pub fn warning(&self) -> Option<String> {
        let (index, line) = self.first_dropped?;
        Some(format!(
            "{} face(s) with fewer than 3 vertices dropped (first: face {index}{})",
            self.dropped_faces,
            line.map(|l| format!(", line {l}")).unwrap_or_default()
        ))
    }
}

/// Read a PLY file (`.ply` memory-mapped, `.ply.gz` decompressed).
pub fn read_ply(path: &Path) -> Result<Mesh, PlyError> {
    read_ply_report(path).map(|(m, _)| m)
}

/// [`read_ply`], also saying what was dropped.
pub fn read_ply_report(path: &Path) -> Result<(Mesh, PlyReport), PlyError> {
    let src = SourceBytes::open(path).map_err(PlyError::Read)?;
    parse_ply_report(src.bytes())
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Role {
    Skip,
    Coord(usize),
    Normal(usize),
    Uv(usize),
}

/// Parse PLY bytes into a triangle mesh.
pub fn parse_ply(bytes: &[u8]) -> Result<Mesh, PlyError> {
    parse_ply_report(bytes).map(|(m, _)| m)
}

/// Appends the triangles of `poly` (a fan), or counts it as dropped when it has < 3 vertices.
fn add_polygon(
    mesh: &mut Mesh,
    report: &mut PlyReport,
    poly: &[u32],
    index: usize,
    line: Option<usize>,
) {
    if poly.len() < 3 {
        report.dropped_faces += 1;
        report.first_dropped.get_or_insert((index, line));
        return;
    }
    for k in 2..poly.len() {
        mesh.indices
            .extend_from_slice(&[poly[0], poly[k - 1], poly[k]]);
    }
}

/// Reads binary faces from `*pos` for as long as each is a triangle (count byte 3, three
/// 4-byte indices) whose indices are all in range, appending them to `indices` as
/// [`add_polygon`] would. Returns the index of the first face not read (`count` when all
/// were). A face it stops at is read again by the caller's general loop, which reports
/// errors; this run only ever accepts faces that loop accepts the same way.
///
/// The general loop cost ~190 instructions a triangle (list, range checks, polygon fan);
/// PLY faces were ~4% of the minipbrt set's import instructions (issue 48 item 1).
#[allow(clippy::too_many_arguments)]
#[inline]
fn triangle_run(
    pos: &mut usize,
    bytes: &[u8],
    item: Scalar,
    le: bool,
    vertices: usize,
    mut index: usize,
    count: usize,
    indices: &mut Vec<u32>,
) -> usize {
    const ITEM: usize = 13;
    // Indices at or past `limit` are left to the general loop (it accepts `u32::MAX` when
    // there are more vertices than that; it rejects negative `int`s, whose bit 31 is set).
    let limit = u32::try_from(vertices).unwrap_or(u32::MAX);
    let signed = item == Scalar::I32;
    let word = |b: &[u8]| {
        let b = [b[0], b[1], b[2], b[3]];
        if le {
            u32::from_le_bytes(b)
        } else {
            u32::from_be_bytes(b)
        }
    };
    let mut p = *pos;
    while index < count {
        let Some(rec) = bytes.get(p..p + ITEM) else {
            break;
        };
        if rec[0] != 3 {
            break;
        }
        let (a, b, c) = (word(&rec[1..5]), word(&rec[5..9]), word(&rec[9..13]));
        let in_range = a < limit && b < limit && c < limit;
        if !in_range || (signed && (a | b | c) >> 31 != 0) {
            break;
        }
        indices.extend_from_slice(&[a, b, c]);
        p += ITEM;
        index += 1;
    }
    *pos = p;
    index
}

/// [`parse_ply`], also saying what was dropped.
pub fn parse_ply_report(bytes: &[u8]) -> Result<(Mesh, PlyReport), PlyError> {
    let (format, elements, body_start) = parse_header(bytes)?;
    let mut report = PlyReport::default();
    let mut body = Body {
        bytes,
        pos: body_start,
        format,
        line: 1 + bytes[..body_start].iter().filter(|&&b| b == b'\n').count(),
        line_end: bytes.len(),
    };
    let mut mesh = Mesh::default();
    let mut normals: Vec<[f32; 3]> = Vec::new();
    let mut uvs: Vec<[f32; 2]> = Vec::new();
    let (mut have_normals, mut have_uvs) = (false, false);
    let mut vertex_count = None;
    // A header can claim any count; never reserve more than the body could hold.
    let reserve_cap = bytes.len().saturating_sub(body_start) / 3;
    for el in &elements {
        // Every item of an element with properties consumes at least one byte: a count
        // beyond the bytes left is a hostile header, not a reason to loop 10^17 times.
        let remaining = bytes.len().saturating_sub(body.pos);
        if let Some(first) = el.props.first() {
            if el.count > remaining {
                return Err(body_err(
                    el,
                    first,
                    remaining,
                    &format!(
                        "truncated: {} items declared, {remaining} bytes left",
                        el.count
                    ),
                ));
            }
        }
        // An element without properties stores nothing per item, whatever its name: its
        // count (any u64 the header claims) must not drive a loop.
        if el.props.is_empty() && el.name != "vertex" {
            continue;
        }
        match el.name.as_str() {
            "vertex" => {
                let roles: Vec<Role> = el.props.iter().map(|p| vertex_role(&p.name)).collect();
                let has = |r: Role| roles.contains(&r);
                if !(has(Role::Coord(0)) && has(Role::Coord(1)) && has(Role::Coord(2))) {
                    return Err(PlyError::Content("vertex element lacks x, y or z".into()));
                }
                have_normals = (0..3).all(|i| has(Role::Normal(i)));
                have_uvs = (0..2).all(|i| has(Role::Uv(i)));
                let n = el.count.min(reserve_cap);
                mesh.positions.reserve(n);
                if have_normals {
                    normals.reserve(n);
                }
                if have_uvs {
                    uvs.reserve(n);
                }
                let fixed = format != Format::Ascii
                    && el
                        .props
                        .iter()
                        .all(|p| matches!(p.kind, PropKind::Scalar(_)));
                if fixed {
                    // Fixed stride: decode only the used properties at known offsets.
                    let mut used = Vec::new();
                    let mut stride = 0;
                    for (prop, role) in el.props.iter().zip(&roles) {
                        if let PropKind::Scalar(s) = prop.kind {
                            if *role != Role::Skip {
                                used.push((stride, s, *role));
                            }
                            stride += s.size();
                        }
                    }
                    let avail = (bytes.len() - body.pos) / stride.max(1);
                    if avail < el.count {
                        return Err(body_err(el, &el.props[0], avail, "truncated"));
                    }
                    let le = format == Format::BinaryLe;
                    let data = &bytes[body.pos..body.pos + stride * el.count];
                    let all_f32 = used.iter().all(|&(_, s, _)| s == Scalar::F32);
                    for item in data.chunks_exact(stride.max(1)).take(el.count) {
                        let (mut p, mut nrm, mut uv) = ([0f32; 3], [0f32; 3], [0f32; 2]);
                        for &(off, s, role) in &used {
                            // The common all-float layout skips the generic f64 decode.
                            let v = match (all_f32, item.get(off..off + 4)) {
                                (true, Some(b)) => {
                                    let b: [u8; 4] = [b[0], b[1], b[2], b[3]];
                                    if le {
                                        f32::from_le_bytes(b)
                                    } else {
                                        f32::from_be_bytes(b)
                                    }
                                }
                                _ => decode(&item[off..], s, le).unwrap_or(0.0) as f32,
                            };
                            match role {
                                Role::Coord(i) => p[i] = v,
                                Role::Normal(i) => nrm[i] = v,
                                Role::Uv(i) => uv[i] = v,
                                Role::Skip => {}
                            }
                        }
                        mesh.positions.push(p);
                        if have_normals {
                            normals.push(nrm);
                        }
                        if have_uvs {
                            uvs.push(uv);
                        }
                    }
                    body.pos += stride * el.count;
                    vertex_count = Some(el.count);
                    continue;
                }
                for index in 0..el.count {
                    let (p, nrm, uv) = body.item(el, index, |body| {
                        let (mut p, mut nrm, mut uv) = ([0f32; 3], [0f32; 3], [0f32; 2]);
                        for (prop, role) in el.props.iter().zip(&roles) {
                            match (&prop.kind, role) {
                                (PropKind::Scalar(s), role) => {
                                    let v = body.read(*s).ok_or_else(|| {
                                        body_err(el, prop, index, "truncated or malformed")
                                    })? as f32;
                                    match *role {
                                        Role::Coord(i) => p[i] = v,
                                        Role::Normal(i) => nrm[i] = v,
                                        Role::Uv(i) => uv[i] = v,
                                        Role::Skip => {}
                                    }
                                }
                                (PropKind::List { count, item }, _) => {
                                    skip_list(body, *count, *item, el, prop, index)?
                                }
                            }
                        }
                        Ok((p, nrm, uv))
                    })?;
                    mesh.positions.push(p);
                    if have_normals {
                        normals.push(nrm);
                    }
                    if have_uvs {
                        uvs.push(uv);
                    }
                }
                vertex_count = Some(el.count);
            }
            "face" => {
                let nv = vertex_count.ok_or_else(|| {
                    PlyError::Content("face element before vertex element".into())
                })?;
                if el.props.is_empty() {
                    continue;
                }
                mesh.indices.reserve(el.count.min(reserve_cap) * 3);
                let mut poly: Vec<u32> = Vec::with_capacity(8);
                if let [prop @ Property {
                    kind:
                        PropKind::List {
                            count: Scalar::U8,
                            item: item @ (Scalar::I32 | Scalar::U32),
                        },
                    ..
                }] = el.props.as_slice()
                {
                    if format != Format::Ascii
                        && matches!(prop.name.as_str(), "vertex_indices" | "vertex_index")
                    {
                        // The layout nearly every binary PLY uses: no f64 round trip.
                        let le = format == Format::BinaryLe;
                        let mut index = 0;
                        while index < el.count {
                            // Runs of triangles go straight into the index buffer; the loop
                            // below takes one face whenever the run stops (a polygon, an index
                            // it does not vouch for: errors are that loop's).
                            index = triangle_run(
                                &mut body.pos,
                                bytes,
                                *item,
                                le,
                                nv,
                                index,
                                el.count,
                                &mut mesh.indices,
                            );
                            if index == el.count {
                                break;
                            }
                            let n = *bytes
                                .get(body.pos)
                                .ok_or_else(|| body_err(el, prop, index, "truncated list count"))?
                                as usize;
                            let start = body.pos + 1;
                            let data = bytes.get(start..start + 4 * n).ok_or_else(|| {
                                body_err(el, prop, index, "truncated or malformed")
                            })?;
                            body.pos = start + 4 * n;
                            poly.clear();
                            for c in data.chunks_exact(4) {
                                let c = [c[0], c[1], c[2], c[3]];
                                let v = if le {
                                    u32::from_le_bytes(c)
                                } else {
                                    u32::from_be_bytes(c)
                                };
                                let negative = *item == Scalar::I32 && (v as i32) < 0;
                                if negative || v as usize >= nv {
                                    let shown = if negative {
                                        i64::from(v as i32)
                                    } else {
                                        i64::from(v)
                                    };
                                    return Err(body_err(
                                        el,
                                        prop,
                                        index,
                                        &format!(
                                            "vertex index {shown} out of range ({nv} vertices)"
                                        ),
                                    ));
                                }
                                poly.push(v);
                            }
                            add_polygon(&mut mesh, &mut report, &poly, index, None);
                            index += 1;
                        }
                        continue;
                    }
                }
                // pbrt's `face_indices`: each face's Ptex face id, kept per triangle (a quad's
                // second triangle marked as its second half).
                let with_faces = el
                    .props
                    .iter()
                    .any(|p| p.name == "face_indices" && matches!(p.kind, PropKind::Scalar(_)));
                let mut face_ids: Vec<u32> = Vec::new();
                for index in 0..el.count {
                    let line = (format == Format::Ascii).then_some(body.line);
                    let before = mesh.indices.len() / 3;
                    let mut face = index as u32;
                    let mut corners = 0;
                    body.item(el, index, |body| {
                        for prop in &el.props {
                            match (&prop.kind, prop.name.as_str()) {
                                (
                                    PropKind::List { count, item },
                                    "vertex_indices" | "vertex_index",
                                ) => {
                                    poly.clear();
                                    let n = read_count(body, *count, el, prop, index)?;
                                    for _ in 0..n {
                                        let v = read_index(body, *item, el, prop, index, nv)?;
                                        poly.push(v);
                                    }
                                    corners = n;
                                    // The item's line is known only after `item` found it.
                                    let line = line.map(|_| body.line);
                                    add_polygon(&mut mesh, &mut report, &poly, index, line);
                                }
                                (PropKind::Scalar(sc), "face_indices") => {
                                    let v = body.read(*sc).ok_or_else(|| {
                                        body_err(el, prop, index, "truncated or malformed")
                                    })?;
                                    if !(v >= 0.0 && v.fract() == 0.0 && v < 2_147_483_648.0) {
                                        return Err(body_err(
                                            el,
                                            prop,
                                            index,
                                            &format!("bad face index {v}"),
                                        ));
                                    }
                                    face = v as u32;
                                }
                                _ => skip_property(body, el, prop, index)?,
                            }
                        }
                        Ok(())
                    })?;
                    if with_faces {
                        let added = mesh.indices.len() / 3 - before;
                        for k in 0..added {
                            let half = k == 1 && corners == 4;
                            face_ids.push(if half {
                                face | crate::events::FACE_SECOND_HALF
                            } else {
                                face
                            });
                        }
                    }
                }
                if with_faces {
                    mesh.face_ids = Some(face_ids);
                }
            }
            "tristrips" => {
                let nv = vertex_count.ok_or_else(|| {
                    PlyError::Content("tristrips element before vertex element".into())
                })?;
                for index in 0..el.count {
                    body.item(el, index, |body| {
                        for prop in &el.props {
                            match (&prop.kind, prop.name.as_str()) {
                                (
                                    PropKind::List { count, item },
                                    "vertex_indices" | "vertex_index",
                                ) => {
                                    let n = read_count(body, *count, el, prop, index)?;
                                    // Strips separated by -1; every triangle alternates its
                                    // winding; zero-area joins (repeated indices) are skipped.
                                    let mut strip: Vec<u32> = Vec::new();
                                    for k in 0..=n {
                                        let v = if k < n {
                                            let v = body.read(*item).ok_or_else(|| {
                                                body_err(el, prop, index, "truncated or malformed")
                                            })?;
                                            if v == -1.0 {
                                                None
                                            } else {
                                                Some(check_index(v, el, prop, index, nv)?)
                                            }
                                        } else {
                                            None
                                        };
                                        match v {
                                            Some(v) => strip.push(v),
                                            None => {
                                                for j in 2..strip.len() {
                                                    let (a, b, c) =
                                                        (strip[j - 2], strip[j - 1], strip[j]);
                                                    if a == b || b == c || a == c {
                                                        continue;
                                                    }
                                                    let tri = if j % 2 == 0 {
                                                        [a, b, c]
                                                    } else {
                                                        [b, a, c]
                                                    };
                                                    mesh.indices.extend_from_slice(&tri);
                                                }
                                                strip.clear();
                                            }
                                        }
                                    }
                                }
                                _ => skip_property(body, el, prop, index)?,
                            }
                        }
                        Ok(())
                    })?;
                }
            }
            _ => {
                for index in 0..el.count {
                    body.item(el, index, |body| {
                        for prop in &el.props {
                            skip_property(body, el, prop, index)?;
                        }
                        Ok(())
                    })?;
                }
            }
        }
    }
    if vertex_count.is_none() {
        return Err(PlyError::Content("no vertex element".into()));
    }
    check_body_end(&body, &elements)?;
    mesh.normals = have_normals.then_some(normals);
    mesh.uvs = have_uvs.then_some(uvs);
    Ok((mesh, report))
}

/// Data after the last declared item is an error, not silently dropped: a body holding more
/// faces (or anything) than the header declares names where the surplus starts (its line in
/// an ASCII file, its byte offset in a binary one). A binary file may end in a newline.
fn check_body_end(body: &Body<'_>, elements: &[Element]) -> Result<(), PlyError> {
    let rest = body.bytes.get(body.pos..).unwrap_or(&[]);
    let Some(first) = rest.iter().position(|b| !body::is_space(b)) else {
        return Ok(());
    };
    let Some(last) = elements.last() else {
        return Ok(());
    };
    let property = last.props.first().map_or(String::new(), |p| p.name.clone());
    let at = if body.format == Format::Ascii {
        let line = body.line + rest[..first].iter().filter(|&&b| b == b'\n').count();
        format!("line {line}")
    } else {
        format!("byte {}", body.pos + first)
    };
    Err(PlyError::Body {
        element: last.name.clone(),
        property,
        index: last.count,
        message: format!(
            "{at}: {} byte(s) of data after the {} declared `{}` item(s), the last element: \
             the body holds more than the header declares (fix the header's count)",
            rest.len() - first,
            last.count,
            last.name
        ),
    })
}

/// One vertex index of a face list, checked against the vertex count.
fn read_index(
    body: &mut Body<'_>,
    item: Scalar,
    el: &Element,
    prop: &Property,
    index: usize,
    nv: usize,
) -> Result<u32, PlyError> {
    let v = body
        .read(item)
        .ok_or_else(|| body_err(el, prop, index, "truncated or malformed"))?;
    check_index(v, el, prop, index, nv)
}

fn check_index(
    v: f64,
    el: &Element,
    prop: &Property,
    index: usize,
    nv: usize,
) -> Result<u32, PlyError> {
    if !(v >= 0.0 && (v as usize) < nv && v.fract() == 0.0) {
        return Err(body_err(
            el,
            prop,
            index,
            &format!("vertex index {v} out of range ({nv} vertices)"),
        ));
    }
    Ok(v as u32)
}

fn vertex_role(name: &str) -> Role {
    match name {
        "x" => Role::Coord(0),
        "y" => Role::Coord(1),
        "z" => Role::Coord(2),
        "nx" => Role::Normal(0),
        "ny" => Role::Normal(1),
        "nz" => Role::Normal(2),
        "u" | "s" | "texture_u" | "texture_s" => Role::Uv(0),
        "v" | "t" | "texture_v" | "texture_t" => Role::Uv(1),
        _ => Role::Skip,
    }
}

fn read_count(
    body: &mut Body<'_>,
    count: Scalar,
    el: &Element,
    prop: &Property,
    index: usize,
) -> Result<usize, PlyError> {
    let n = body
        .read(count)
        .ok_or_else(|| body_err(el, prop, index, "truncated list count"))?;
    if !(n >= 0.0 && n.fract() == 0.0 && n < 1e9) {
        return Err(body_err(el, prop, index, &format!("bad list count {n}")));
    }
    Ok(n as usize)
}

/// Reads past a property this reader does not store (a scalar or a whole list).
fn skip_property(
    body: &mut Body<'_>,
    el: &Element,
    prop: &Property,
    index: usize,
) -> Result<(), PlyError> {
    match &prop.kind {
        PropKind::Scalar(s) => {
            body.read(*s)
                .ok_or_else(|| body_err(el, prop, index, "truncated or malformed"))?;
            Ok(())
        }
        PropKind::List { count, item } => skip_list(body, *count, *item, el, prop, index),
    }
}

fn skip_list(
    body: &mut Body<'_>,
    count: Scalar,
    item: Scalar,
    el: &Element,
    prop: &Property,
    index: usize,
) -> Result<(), PlyError> {
    let n = read_count(body, count, el, prop, index)?;
    if body.format == Format::Ascii {
        for _ in 0..n {
            body.read_ascii()
                .ok_or_else(|| body_err(el, prop, index, "truncated or malformed"))?;
        }
    } else {
        let len = n * item.size();
        if body.pos + len > body.bytes.len() {
            return Err(body_err(el, prop, index, "truncated list"));
        }
        body.pos += len;
    }
    Ok(())
}

#[cfg(test)]
mod tests;
