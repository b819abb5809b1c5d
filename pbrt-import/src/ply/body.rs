//! Reading element items from the PLY body: ASCII words (one item per line) or binary scalars
//! of either byte order, with errors naming the element, property and item.

use super::header::{Element, Format, Property, Scalar};
use crate::error::PlyError;

/// Value source over the body: ASCII words or binary scalars.
pub(super) struct Body<'a> {
    pub(super) bytes: &'a [u8],
    pub(super) pos: usize,
    pub(super) format: Format,
    /// ASCII: the 1-based line at `pos` and the end of the current item's line (values are
    /// read only up to it).
    pub(super) line: usize,
    pub(super) line_end: usize,
}

pub(super) fn is_space(b: &u8) -> bool {
    b.is_ascii_whitespace()
}

impl Body<'_> {
    /// Runs `f` over one element item. ASCII: the item is the next non-blank line; `f` reads
    /// only from it, and values left over are an error; errors name the line.
    pub(super) fn item<T>(
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
    pub(super) fn read(&mut self, s: Scalar) -> Option<f64> {
        if self.format == Format::Ascii {
            return self.read_ascii();
        }
        let n = s.size();
        let b = self.bytes.get(self.pos..self.pos + n)?;
        self.pos += n;
        decode(b, s, self.format == Format::BinaryLe)
    }

    pub(super) fn read_ascii(&mut self) -> Option<f64> {
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
pub(super) fn decode(b: &[u8], s: Scalar, le: bool) -> Option<f64> {
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

pub(super) fn body_err(el: &Element, prop: &Property, index: usize, message: &str) -> PlyError {
    PlyError::Body {
        element: el.name.clone(),
        property: prop.name.clone(),
        index,
        message: message.into(),
    }
}
