//! PLY reader: ASCII and binary (little/big endian), `.ply.gz`, any property types.
//!
//! Faces (triangles, quads, polygons) are fan-triangulated; `tristrips` elements (strips
//! separated by -1) are unrolled. Faces of fewer than 3 vertices are dropped and counted
//! ([`PlyReport`]). Vertex normals come from `nx ny nz`; texture coordinates from any of
//! pbrt's names (`u v`, `s t`, `texture_u texture_v`, `texture_s texture_t`). `face_indices`
//! and other properties/elements are read and skipped. ASCII bodies hold one element item
//! per line (the PLY rule): a missing or extra value is an error naming the line.

use std::path::Path;

use crate::error::PlyError;
use crate::events::Mesh;
use crate::source::SourceBytes;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(s: &str) -> Option<Scalar> {
        Some(match s {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
}

#[derive(Clone, Debug)]
enum PropKind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Clone, Debug)]
struct Property {
    name: String,
    kind: PropKind,
}

#[derive(Clone, Debug)]
struct Element {
    name: String,
    count: usize,
    props: Vec<Property>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Format {
    Ascii,
    BinaryLe,
    BinaryBe,
}

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
    let src =
        SourceBytes::open(path).map_err(|e| PlyError::Content(format!("cannot read: {e}")))?;
    parse_ply_report(src.bytes())
}

fn header_err(line: usize, message: impl Into<String>) -> PlyError {
    PlyError::Header {
        line,
        message: message.into(),
    }
}

fn parse_header(bytes: &[u8]) -> Result<(Format, Vec<Element>, usize), PlyError> {
    let mut pos = 0;
    let mut line_no = 0;
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        line_no += 1;
        let Some(nl) = bytes[pos..].iter().position(|&b| b == b'\n') else {
            return Err(header_err(line_no, "header ends without `end_header`"));
        };
        let raw = &bytes[pos..pos + nl];
        pos += nl + 1;
        let line = std::str::from_utf8(raw)
            .map_err(|_| header_err(line_no, "not UTF-8"))?
            .trim_end_matches('\r');
        let words: Vec<&str> = line.split_ascii_whitespace().collect();
        if line_no == 1 {
            if words != ["ply"] {
                return Err(header_err(1, "missing `ply` magic"));
            }
            continue;
        }
        match words.as_slice() {
            [] => {}
            ["comment", ..] | ["obj_info", ..] => {}
            ["format", f, _version] => {
                format = Some(match *f {
                    "ascii" => Format::Ascii,
                    "binary_little_endian" => Format::BinaryLe,
                    "binary_big_endian" => Format::BinaryBe,
                    other => return Err(header_err(line_no, format!("unknown format `{other}`"))),
                });
            }
            ["element", name, count] => {
                let count = count
                    .parse()
                    .map_err(|_| header_err(line_no, format!("bad element count `{count}`")))?;
                elements.push(Element {
                    name: (*name).to_owned(),
                    count,
                    props: Vec::new(),
                });
            }
            ["property", "list", ct, it, name] => {
                let el = elements
                    .last_mut()
                    .ok_or_else(|| header_err(line_no, "property before element"))?;
                let count = Scalar::parse(ct)
                    .ok_or_else(|| header_err(line_no, format!("unknown type `{ct}`")))?;
                let item = Scalar::parse(it)
                    .ok_or_else(|| header_err(line_no, format!("unknown type `{it}`")))?;
                if matches!(count, Scalar::F32 | Scalar::F64) {
                    return Err(header_err(line_no, "list count type must be an integer"));
                }
                el.props.push(Property {
                    name: (*name).to_owned(),
                    kind: PropKind::List { count, item },
                });
            }
            ["property", ty, name] => {
                let el = elements
                    .last_mut()
                    .ok_or_else(|| header_err(line_no, "property before element"))?;
                let s = Scalar::parse(ty)
                    .ok_or_else(|| header_err(line_no, format!("unknown type `{ty}`")))?;
                el.props.push(Property {
                    name: (*name).to_owned(),
                    kind: PropKind::Scalar(s),
                });
            }
            ["end_header"] => break,
            _ => return Err(header_err(line_no, format!("unrecognised line `{line}`"))),
        }
    }
    let format = format.ok_or_else(|| header_err(line_no, "no `format` line"))?;
    Ok((format, elements, pos))
}

/// Value source over the body: ASCII words or binary scalars.
struct Body<'a> {
    bytes: &'a [u8],
    pos: usize,
    format: Format,
    /// ASCII: the 1-based line at `pos` and the end of the current item's line (values are
    /// read only up to it).
    line: usize,
    line_end: usize,
}

fn is_space(b: &u8) -> bool {
    b.is_ascii_whitespace()
}

impl Body<'_> {
    /// Runs `f` over one element item. ASCII: the item is the next non-blank line; `f` reads
    /// only from it, and values left over are an error; errors name the line.
    fn item<T>(
        &mut self,
        el: &Element,
        index: usize,
        f: impl FnOnce(&mut Self) -> Result<T, PlyError>,
    ) -> Result<T, PlyError> {
        if self.format != Format::Ascii {
            return f(self);
        }
        let first = el.props.first().map_or("", |p| p.name.as_str());
        let err = |line: usize, message: String| PlyError::Body {
            element: el.name.clone(),
            property: first.to_owned(),
            index,
            message: format!("line {line}: {message}"),
        };
        loop {
            if self.pos >= self.bytes.len() {
                return Err(err(
                    self.line,
                    format!("the file ends before item {index} of {}", el.count),
                ));
            }
            let end = self.bytes[self.pos..]
                .iter()
                .position(|&b| b == b'\n')
                .map_or(self.bytes.len(), |n| self.pos + n);
            if self.bytes[self.pos..end].iter().all(is_space) {
                self.pos = end + 1;
                self.line += 1;
                continue;
            }
            self.line_end = end;
            break;
        }
        let line = self.line;
        let r = f(self).map_err(|e| match e {
            PlyError::Body {
                element,
                property,
                index,
                message,
            } => PlyError::Body {
                element,
                property,
                index,
                message: format!(
                    "line {line}: {}",
                    if message == "truncated or malformed" {
                        "a value is missing or malformed (an ASCII PLY item is one line)"
                    } else {
                        &message
                    }
                ),
            },
            other => other,
        })?;
        if !self.bytes[self.pos..self.line_end].iter().all(is_space) {
            return Err(err(
                line,
                "more values than the header declares for this element".into(),
            ));
        }
        self.pos = (self.line_end + 1).min(self.bytes.len());
        self.line += 1;
        self.line_end = self.bytes.len();
        Ok(r)
    }

    #[inline]
    fn read(&mut self, s: Scalar) -> Option<f64> {
        if self.format == Format::Ascii {
            return self.read_ascii();
        }
        let n = s.size();
        let b = self.bytes.get(self.pos..self.pos + n)?;
        self.pos += n;
        decode(b, s, self.format == Format::BinaryLe)
    }

    fn read_ascii(&mut self) -> Option<f64> {
        let bytes = &self.bytes[..self.line_end.min(self.bytes.len())];
        while self.pos < bytes.len() && bytes[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        let start = self.pos;
        while self.pos < bytes.len() && !bytes[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        crate::lexer::parse_f64(&bytes[start..self.pos])
    }
}

/// Decode one binary scalar from the start of `b`.
#[inline]
fn decode(b: &[u8], s: Scalar, le: bool) -> Option<f64> {
    macro_rules! get {
        ($t:ty) => {{
            let arr = b.get(..std::mem::size_of::<$t>())?.try_into().ok()?;
            if le {
                <$t>::from_le_bytes(arr)
            } else {
                <$t>::from_be_bytes(arr)
            }
        }};
    }
    Some(match s {
        Scalar::I8 => f64::from(*b.first()? as i8),
        Scalar::U8 => f64::from(*b.first()?),
        Scalar::I16 => f64::from(get!(i16)),
        Scalar::U16 => f64::from(get!(u16)),
        Scalar::I32 => f64::from(get!(i32)),
        Scalar::U32 => f64::from(get!(u32)),
        Scalar::F32 => f64::from(get!(f32)),
        Scalar::F64 => get!(f64),
    })
}

fn body_err(el: &Element, prop: &Property, index: usize, message: &str) -> PlyError {
    PlyError::Body {
        element: el.name.clone(),
        property: prop.name.clone(),
        index,
        message: message.into(),
    }
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
                        for index in 0..el.count {
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
                        }
                        continue;
                    }
                }
                for index in 0..el.count {
                    let line = (format == Format::Ascii).then_some(body.line);
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
                                    // The item's line is known only after `item` found it.
                                    let line = line.map(|_| body.line);
                                    add_polygon(&mut mesh, &mut report, &poly, index, line);
                                }
                                (PropKind::List { count, item }, _) => {
                                    skip_list(body, *count, *item, el, prop, index)?
                                }
                                (PropKind::Scalar(s), _) => {
                                    body.read(*s).ok_or_else(|| {
                                        body_err(el, prop, index, "truncated or malformed")
                                    })?;
                                }
                            }
                        }
                        Ok(())
                    })?;
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
                                (PropKind::List { count, item }, _) => {
                                    skip_list(body, *count, *item, el, prop, index)?
                                }
                                (PropKind::Scalar(s), _) => {
                                    body.read(*s).ok_or_else(|| {
                                        body_err(el, prop, index, "truncated or malformed")
                                    })?;
                                }
                            }
                        }
                        Ok(())
                    })?;
                }
            }
            _ if el.props.is_empty() => {} // nothing stored per item
            _ => {
                for index in 0..el.count {
                    body.item(el, index, |body| {
                        for prop in &el.props {
                            match &prop.kind {
                                PropKind::Scalar(s) => {
                                    body.read(*s).ok_or_else(|| {
                                        body_err(el, prop, index, "truncated or malformed")
                                    })?;
                                }
                                PropKind::List { count, item } => {
                                    skip_list(body, *count, *item, el, prop, index)?
                                }
                            }
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
    mesh.normals = have_normals.then_some(normals);
    mesh.uvs = have_uvs.then_some(uvs);
    Ok((mesh, report))
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

/// Write a mesh as binary little-endian PLY (tests, fuzz seeds, the pbrt writer).
pub fn write_ply_binary_le(mesh: &Mesh) -> Vec<u8> {
    let mut out = Vec::new();
    let mut header = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\n",
        mesh.positions.len()
    );
    header.push_str("property float x\nproperty float y\nproperty float z\n");
    if mesh.normals.is_some() {
        header.push_str("property float nx\nproperty float ny\nproperty float nz\n");
    }
    if mesh.uvs.is_some() {
        header.push_str("property float u\nproperty float v\n");
    }
    header.push_str(&format!(
        "element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        mesh.indices.len() / 3
    ));
    out.extend_from_slice(header.as_bytes());
    for (i, p) in mesh.positions.iter().enumerate() {
        p.iter()
            .for_each(|c| out.extend_from_slice(&c.to_le_bytes()));
        if let Some(n) = mesh.normals.as_ref().and_then(|n| n.get(i)) {
            n.iter()
                .for_each(|c| out.extend_from_slice(&c.to_le_bytes()));
        }
        if let Some(uv) = mesh.uvs.as_ref().and_then(|u| u.get(i)) {
            uv.iter()
                .for_each(|c| out.extend_from_slice(&c.to_le_bytes()));
        }
    }
    for t in mesh.indices.chunks_exact(3) {
        out.push(3);
        t.iter()
            .for_each(|&i| out.extend_from_slice(&(i as i32).to_le_bytes()));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const ASCII_QUAD: &str = "ply\nformat ascii 1.0\ncomment x\nelement vertex 4\nproperty float x\nproperty float y\n\
        property float z\nproperty float s\nproperty float t\nelement face 1\nproperty list uchar int vertex_indices\n\
        end_header\n0 0 0 0 0\n1 0 0 1 0\n1 1 0 1 1\n0 1 0 0 1\n4 0 1 2 3\n";

    #[test]
    fn ascii_quad_with_st() {
        let m = parse_ply(ASCII_QUAD.as_bytes()).unwrap();
        assert_eq!(m.positions.len(), 4);
        assert_eq!(m.indices, [0, 1, 2, 0, 2, 3]);
        assert_eq!(m.uvs.unwrap()[2], [1.0, 1.0]);
        assert!(m.normals.is_none());
    }

    #[test]
    fn binary_le_roundtrip() {
        let mesh = Mesh {
            positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            normals: Some(vec![[0.0, 0.0, 1.0]; 3]),
            uvs: Some(vec![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]),
            indices: vec![0, 1, 2],
        };
        assert_eq!(parse_ply(&write_ply_binary_le(&mesh)).unwrap(), mesh);
    }

    #[test]
    fn binary_be_with_extra_props_and_elements() {
        let mut b = b"ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty double x\nproperty double y\n\
            property double z\nproperty uchar red\nelement face 1\nproperty list uint short vertex_indices\n\
            property list uchar int face_indices\nelement edge 1\nproperty int a\nend_header\n"
            .to_vec();
        for p in [[0.0f64, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0]] {
            p.iter().for_each(|c| b.extend_from_slice(&c.to_be_bytes()));
            b.push(255);
        }
        b.extend_from_slice(&3u32.to_be_bytes());
        for i in [2i16, 1, 0] {
            b.extend_from_slice(&i.to_be_bytes());
        }
        b.push(1);
        b.extend_from_slice(&7i32.to_be_bytes());
        b.extend_from_slice(&9i32.to_be_bytes());
        let m = parse_ply(&b).unwrap();
        assert_eq!(m.positions[1], [2.0, 0.0, 0.0]);
        assert_eq!(m.indices, [2, 1, 0]);
    }

    #[test]
    fn errors_name_element_and_property() {
        let bad = ASCII_QUAD.replace("4 0 1 2 3", "4 0 1 2 9");
        let e = parse_ply(bad.as_bytes()).unwrap_err().to_string();
        assert!(
            e.contains("`face` property `vertex_indices`") && e.contains("out of range"),
            "{e}"
        );
        let trunc = &ASCII_QUAD.as_bytes()[..ASCII_QUAD.len() - 8];
        assert!(parse_ply(trunc)
            .unwrap_err()
            .to_string()
            .contains("vertex_indices"));
        assert!(parse_ply(
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty foo x\nend_header\n"
        )
        .is_err());
        assert!(parse_ply(b"plx\n").is_err());
        assert!(parse_ply(b"ply\nformat ascii 1.0\nelement vertex 99999999999\nproperty float x\nproperty float y\nproperty float z\nend_header\n").is_err());
        assert!(parse_ply(b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\nend_header\n").is_err());
    }

    const TRI_HEAD: &str = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n";

    #[test]
    fn regression_ply_ascii_missing_value_names_the_line() {
        let ply = format!("{TRI_HEAD}element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0\n1 1 0\n0 1 0\n3 0 1 2\n");
        let e = parse_ply(ply.as_bytes()).unwrap_err().to_string();
        assert!(e.contains("line 11") && e.contains("missing"), "{e}");
        let extra = format!("{TRI_HEAD}element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0 7\n1 1 0\n0 1 0\n3 0 1 2\n");
        let e = parse_ply(extra.as_bytes()).unwrap_err().to_string();
        assert!(e.contains("line 11") && e.contains("more values"), "{e}");
        // Blank lines between items are fine.
        let blank = format!("{TRI_HEAD}element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n");
        assert_eq!(parse_ply(blank.as_bytes()).unwrap().indices, vec![0, 1, 2]);
    }

    #[test]
    fn regression_ply_tristrips_become_triangles() {
        // Two strips separated by -1; the second joins back with a repeated index (skipped).
        let ply = format!("{TRI_HEAD}element tristrips 1\nproperty list int int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n9 0 1 2 3 -1 3 3 2 1\n");
        let m = parse_ply(ply.as_bytes()).unwrap();
        assert_eq!(m.indices, vec![0, 1, 2, 2, 1, 3, 2, 3, 1]);
        // Binary little-endian too.
        let mut bin = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement tristrips 1\nproperty list int int vertex_indices\nend_header\n".to_vec();
        for v in [0f32, 0., 0., 1., 0., 0., 0., 1., 0.] {
            bin.extend_from_slice(&v.to_le_bytes());
        }
        for i in [3i32, 0, 1, 2] {
            bin.extend_from_slice(&i.to_le_bytes());
        }
        assert_eq!(parse_ply(&bin).unwrap().indices, vec![0, 1, 2]);
        let bad = format!("{TRI_HEAD}element tristrips 1\nproperty list int int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 7\n");
        assert!(parse_ply(bad.as_bytes())
            .unwrap_err()
            .to_string()
            .contains("out of range"));
    }

    #[test]
    fn regression_ply_degenerate_faces_are_counted() {
        let ply = format!("{TRI_HEAD}element face 3\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n0\n2 0 1\n");
        let (m, r) = parse_ply_report(ply.as_bytes()).unwrap();
        assert_eq!(m.indices, vec![0, 1, 2]);
        assert_eq!(r.dropped_faces, 2);
        assert_eq!(r.first_dropped, Some((1, Some(15))));
        assert!(r.warning().unwrap().contains("2 face(s)"));
        // The binary fast path counts them too.
        let mut bin = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n".to_vec();
        for v in [0f32, 0., 0., 1., 0., 0., 0., 1., 0.] {
            bin.extend_from_slice(&v.to_le_bytes());
        }
        bin.push(3);
        for i in [0i32, 1, 2] {
            bin.extend_from_slice(&i.to_le_bytes());
        }
        bin.push(2);
        for i in [0i32, 1] {
            bin.extend_from_slice(&i.to_le_bytes());
        }
        let (m, r) = parse_ply_report(&bin).unwrap();
        assert_eq!(
            (m.indices.len(), r.dropped_faces, r.first_dropped),
            (3, 1, Some((1, None)))
        );
    }

    /// Binary `uchar`/`int` and `uchar`/`uint` face lists take a fast path; it must agree
    /// with the generic reader (ASCII) on quads, bounds and negative indices.
    #[test]
    fn binary_face_fast_path_matches_generic_reader() {
        let header = |format: &str, item: &str| {
            format!(
                "ply\nformat {format} 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
                 property float z\nelement face 2\nproperty list uchar {item} vertex_indices\nend_header\n"
            )
        };
        let faces: [&[i32]; 2] = [&[0, 1, 2, 3], &[3, 2, 1]];
        let positions = [
            [0.0f32, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ];
        let binary = |le: bool, item: &str, faces: &[&[i32]]| {
            let format = if le {
                "binary_little_endian"
            } else {
                "binary_big_endian"
            };
            let mut b = header(format, item).into_bytes();
            for p in positions.iter().flatten() {
                b.extend_from_slice(&if le { p.to_le_bytes() } else { p.to_be_bytes() });
            }
            for f in faces {
                b.push(f.len() as u8);
                for i in *f {
                    b.extend_from_slice(&if le { i.to_le_bytes() } else { i.to_be_bytes() });
                }
            }
            b
        };
        let mut ascii = header("ascii", "int");
        for p in positions {
            ascii += &format!("{} {} {}\n", p[0], p[1], p[2]);
        }
        for f in faces {
            let list: Vec<String> = f.iter().map(i32::to_string).collect();
            ascii += &format!("{} {}\n", f.len(), list.join(" "));
        }
        let generic = parse_ply(ascii.as_bytes()).unwrap();
        assert_eq!(generic.indices, [0, 1, 2, 0, 2, 3, 3, 2, 1]);
        for le in [true, false] {
            for item in ["int", "uint"] {
                assert_eq!(parse_ply(&binary(le, item, &faces)).unwrap(), generic);
                for bad in [-1, 4] {
                    let e = parse_ply(&binary(le, item, &[&[0, 1, bad], &[0, 1, 2]]))
                        .unwrap_err()
                        .to_string();
                    assert!(
                        e.contains("out of range") && e.contains("vertex_indices"),
                        "{e}"
                    );
                }
                let whole = binary(le, item, &faces);
                let e = parse_ply(&whole[..whole.len() - 2])
                    .unwrap_err()
                    .to_string();
                assert!(e.contains("truncated"), "{e}");
            }
        }
    }

    /// Fuzz finding (ply target, timeout): `element ve2rtex 433333333333333334` with no
    /// properties looped 4e17 times doing nothing; and a property-carrying element whose
    /// count exceeds the bytes left now fails at once instead of item by item.
    #[test]
    fn regression_ply_huge_element_count_timeout() {
        let no_props =
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
              property float z\nelement ve2rtex 433333333333333334\nend_header\n0 0 0\n";
        let started = std::time::Instant::now();
        assert_eq!(parse_ply(no_props).unwrap().positions.len(), 1);
        let face = b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n\
              property float y\nproperty float z\nelement face 4000000000\n\
              property list uchar int vertex_indices\nend_header\n\0\0\0\0\0\0\0\0\0\0\0\0";
        let e = parse_ply(face).unwrap_err().to_string();
        assert!(e.contains("4000000000 items declared"), "{e}");
        assert!(started.elapsed() < std::time::Duration::from_secs(1));
    }

    #[test]
    fn gz_file() {
        use std::io::Write;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.ply.gz");
        let mut enc = flate2::write::GzEncoder::new(
            std::fs::File::create(&path).unwrap(),
            flate2::Compression::fast(),
        );
        enc.write_all(ASCII_QUAD.as_bytes()).unwrap();
        enc.finish().unwrap();
        assert_eq!(read_ply(&path).unwrap().triangle_count(), 2);
    }
}
