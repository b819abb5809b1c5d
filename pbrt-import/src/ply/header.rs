//! The PLY header: formats, elements and their properties (scalar and list types).

use crate::error::PlyError;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Scalar {
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
    pub(super) fn parse(s: &str) -> Option<Scalar> {
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

    pub(super) fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
}

#[derive(Clone, Debug)]
pub(super) enum PropKind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Clone, Debug)]
pub(super) struct Property {
    pub(super) name: String,
    pub(super) kind: PropKind,
}

#[derive(Clone, Debug)]
pub(super) struct Element {
    pub(super) name: String,
    pub(super) count: usize,
    pub(super) props: Vec<Property>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Format {
    Ascii,
    BinaryLe,
    BinaryBe,
}

pub(super) fn header_err(line: usize, message: impl Into<String>) -> PlyError {
    PlyError::Header {
        line,
        message: message.into(),
    }
}

pub(super) fn parse_header(bytes: &[u8]) -> Result<(Format, Vec<Element>, usize), PlyError> {
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
