//! A small pull reader for JSON over a byte slice (usually a memory map).
//!
//! Moana's archive files are single JSON objects of up to gigabytes (OBJ path → instance name →
//! 16 numbers) and its curve files lists of millions of point lists: a document tree of them
//! would cost several times the file in RAM. This reader walks the bytes once and hands each
//! key and value to the caller as it is reached, so memory stays that of one matrix or one curve
//! whatever the file's size; small files (elements, materials, cameras) are read into a
//! [`Node`] tree with the same code. Errors carry the byte offset of the fault.
//!
//! Accepted beyond RFC 8259: the `NaN`, `Infinity` and `-Infinity` tokens Python's `json`
//! writes, so that a matrix holding one is refused by its meaning (non-finite), not as syntax.

use std::borrow::Cow;

/// Deepest nesting a tree read may have (user data never overflows the stack).
const MAX_DEPTH: usize = 256;

/// A syntax error at a byte offset.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct JsonError {
    pub offset: usize,
    pub message: String,
}

pub(crate) type JResult<T> = Result<T, JsonError>;

/// A value of a small document, with the byte offset it starts at.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Node {
    pub at: usize,
    pub value: Value,
}

#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Value {
    Null,
    Bool(bool),
    Num(f64),
    Str(String),
    Arr(Vec<Node>),
    /// Members in document order (Moana's maps are ordered by their writers).
    Obj(Vec<(String, Node)>),
}

impl Node {
    /// The member `key` of an object.
    pub fn get(&self, key: &str) -> Option<&Node> {
        match &self.value {
            Value::Obj(m) => m.iter().find(|(k, _)| k == key).map(|(_, v)| v),
            _ => None,
        }
    }

    pub fn as_str(&self) -> Option<&str> {
        match &self.value {
            Value::Str(s) => Some(s),
            _ => None,
        }
    }

    pub fn as_f64(&self) -> Option<f64> {
        match self.value {
            Value::Num(x) => Some(x),
            _ => None,
        }
    }

    pub fn members(&self) -> &[(String, Node)] {
        match &self.value {
            Value::Obj(m) => m,
            _ => &[],
        }
    }

    pub fn items(&self) -> &[Node] {
        match &self.value {
            Value::Arr(a) => a,
            _ => &[],
        }
    }

    pub fn is_obj(&self) -> bool {
        matches!(self.value, Value::Obj(_))
    }
}

/// The reader: a cursor over `bytes`.
pub(crate) struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    pub fn new(bytes: &'a [u8]) -> Self {
        // A UTF-8 byte-order mark is allowed before the document.
        let pos = if bytes.starts_with(b"\xEF\xBB\xBF") {
            3
        } else {
            0
        };
        Reader { bytes, pos }
    }

    pub fn offset(&self) -> usize {
        self.pos
    }

    pub fn err<T>(&self, at: usize, message: impl Into<String>) -> JResult<T> {
        Err(JsonError {
            offset: at,
            message: message.into(),
        })
    }

    /// The error `err` returns, for callers with their own error type.
    pub fn error(&self, at: usize, message: impl Into<String>) -> JsonError {
        JsonError {
            offset: at,
            message: message.into(),
        }
    }

    fn eof<T>(&self, what: &str) -> JResult<T> {
        self.err(
            self.bytes.len(),
            format!("the file ends inside {what} (truncated?)"),
        )
    }

    fn ws(&mut self) {
        while let Some(&b) = self.bytes.get(self.pos) {
            if matches!(b, b' ' | b'\t' | b'\n' | b'\r') {
                self.pos += 1;
            } else {
                break;
            }
        }
    }

    /// The next significant byte, not consumed.
    pub fn peek(&mut self) -> Option<u8> {
        self.ws();
        self.bytes.get(self.pos).copied()
    }

    /// After the document: only whitespace may follow.
    pub fn finish(&mut self) -> JResult<()> {
        match self.peek() {
            None => Ok(()),
            Some(_) => self.err(self.pos, "unexpected data after the JSON document"),
        }
    }

    fn expect(&mut self, b: u8, what: &str) -> JResult<()> {
        match self.peek() {
            Some(x) if x == b => {
                self.pos += 1;
                Ok(())
            }
            Some(x) => self.err(
                self.pos,
                format!("expected {what}, found `{}`", printable(x)),
            ),
            None => self.eof(what),
        }
    }

    /// Calls `f` with each key of an object (after its `:`); `f` must read or skip the value.
    pub fn object<E: From<JsonError>>(
        &mut self,
        what: &str,
        mut f: impl FnMut(&mut Self, Cow<'a, str>, usize) -> Result<(), E>,
    ) -> Result<(), E> {
        self.expect(b'{', what)?;
        if self.peek() == Some(b'}') {
            self.pos += 1;
            return Ok(());
        }
        loop {
            let at = match self.peek() {
                Some(b'"') => self.pos,
                Some(x) => {
                    return self
                        .err(
                            self.pos,
                            format!("expected a key string in {what}, found `{}`", printable(x)),
                        )
                        .map_err(E::from)
                }
                None => return self.eof(what).map_err(E::from),
            };
            let key = self.string()?;
            self.expect(b':', "`:` after a key")?;
            f(self, key, at)?;
            match self.peek() {
                Some(b',') => self.pos += 1,
                Some(b'}') => {
                    self.pos += 1;
                    return Ok(());
                }
                Some(x) => {
                    return self
                        .err(
                            self.pos,
                            format!("expected `,` or `}}` in {what}, found `{}`", printable(x)),
                        )
                        .map_err(E::from)
                }
                None => return self.eof(what).map_err(E::from),
            }
        }
    }

    /// Calls `f` for each item of an array; `f` must read or skip the item.
    pub fn array<E: From<JsonError>>(
        &mut self,
        what: &str,
        mut f: impl FnMut(&mut Self, usize) -> Result<(), E>,
    ) -> Result<(), E> {
        self.expect(b'[', what)?;
        if self.peek() == Some(b']') {
            self.pos += 1;
            return Ok(());
        }
        let mut index = 0;
        loop {
            f(self, index)?;
            index += 1;
            match self.peek() {
                Some(b',') => self.pos += 1,
                Some(b']') => {
                    self.pos += 1;
                    return Ok(());
                }
                Some(x) => {
                    return self
                        .err(
                            self.pos,
                            format!("expected `,` or `]` in {what}, found `{}`", printable(x)),
                        )
                        .map_err(E::from)
                }
                None => return self.eof(what).map_err(E::from),
            }
        }
    }

    /// A string value.
    pub fn string(&mut self) -> JResult<Cow<'a, str>> {
        let start = match self.peek() {
            Some(b'"') => self.pos,
            Some(x) => {
                return self.err(
                    self.pos,
                    format!("expected a string, found `{}`", printable(x)),
                )
            }
            None => return self.eof("a string"),
        };
        self.pos += 1;
        let body = self.pos;
        // Fast path: no escapes.
        while let Some(&b) = self.bytes.get(self.pos) {
            match b {
                b'"' => {
                    let s = std::str::from_utf8(&self.bytes[body..self.pos]).map_err(|_| {
                        JsonError {
                            offset: start,
                            message: "string is not UTF-8".into(),
                        }
                    })?;
                    self.pos += 1;
                    return Ok(Cow::Borrowed(s));
                }
                b'\\' => break,
                0..=0x1f => return self.err(self.pos, "control character inside a string"),
                _ => self.pos += 1,
            }
        }
        if self.pos >= self.bytes.len() {
            return self.eof("a string");
        }
        let mut out: Vec<u8> = self.bytes[body..self.pos].to_vec();
        loop {
            let Some(&b) = self.bytes.get(self.pos) else {
                return self.eof("a string");
            };
            self.pos += 1;
            match b {
                b'"' => break,
                b'\\' => {
                    let Some(&e) = self.bytes.get(self.pos) else {
                        return self.eof("a string");
                    };
                    self.pos += 1;
                    match e {
                        b'"' | b'\\' | b'/' => out.push(e),
                        b'b' => out.push(8),
                        b'f' => out.push(12),
                        b'n' => out.push(b'\n'),
                        b'r' => out.push(b'\r'),
                        b't' => out.push(b'\t'),
                        b'u' => {
                            let mut c = self.hex4()?;
                            if (0xD800..0xDC00).contains(&c)
                                && self.bytes[self.pos..].starts_with(b"\\u")
                            {
                                self.pos += 2;
                                let lo = self.hex4()?;
                                c = 0x10000
                                    + ((c - 0xD800) << 10)
                                    + (lo.wrapping_sub(0xDC00) & 0x3ff);
                            }
                            let ch = char::from_u32(c).unwrap_or('\u{FFFD}');
                            let mut buf = [0u8; 4];
                            out.extend_from_slice(ch.encode_utf8(&mut buf).as_bytes());
                        }
                        _ => return self.err(self.pos - 2, "unknown escape in a string"),
                    }
                }
                0..=0x1f => return self.err(self.pos - 1, "control character inside a string"),
                _ => out.push(b),
            }
        }
        String::from_utf8(out)
            .map(Cow::Owned)
            .map_err(|_| JsonError {
                offset: start,
                message: "string is not UTF-8".into(),
            })
    }

    fn hex4(&mut self) -> JResult<u32> {
        let Some(h) = self.bytes.get(self.pos..self.pos + 4) else {
            return self.eof("a string");
        };
        let s = std::str::from_utf8(h).ok();
        let v = s.and_then(|s| u32::from_str_radix(s, 16).ok());
        match v {
            Some(v) => {
                self.pos += 4;
                Ok(v)
            }
            None => self.err(self.pos, "bad \\u escape"),
        }
    }

    /// A number (also `NaN`, `Infinity`, `-Infinity`).
    pub fn number(&mut self) -> JResult<f64> {
        let start = match self.peek() {
            Some(_) => self.pos,
            None => return self.eof("a number"),
        };
        let rest = &self.bytes[start..];
        for (word, value) in [
            (&b"NaN"[..], f64::NAN),
            (b"Infinity", f64::INFINITY),
            (b"-Infinity", f64::NEG_INFINITY),
        ] {
            if rest.starts_with(word) {
                self.pos += word.len();
                return Ok(value);
            }
        }
        // JSON's grammar: -?(0|[1-9][0-9]*)(\.[0-9]+)?([eE][+-]?[0-9]+)?
        let mut i = 0;
        let digit = |i: usize| rest.get(i).is_some_and(u8::is_ascii_digit);
        if rest.get(i) == Some(&b'-') {
            i += 1;
        }
        if !digit(i) {
            return match rest.get(i) {
                Some(&x) => self.err(
                    start + i,
                    format!("expected a number, found `{}`", printable(x)),
                ),
                None => self.eof("a number"),
            };
        }
        while digit(i) {
            i += 1;
        }
        if rest.get(i) == Some(&b'.') {
            i += 1;
            if !digit(i) {
                return self.err(start + i, "expected a digit after `.`");
            }
            while digit(i) {
                i += 1;
            }
        }
        if matches!(rest.get(i), Some(b'e' | b'E')) {
            i += 1;
            if matches!(rest.get(i), Some(b'+' | b'-')) {
                i += 1;
            }
            if !digit(i) {
                return self.err(start + i, "expected a digit in the exponent");
            }
            while digit(i) {
                i += 1;
            }
        }
        match fast_float2::parse::<f64, _>(&rest[..i]) {
            Ok(v) => {
                self.pos += i;
                Ok(v)
            }
            Err(_) => self.err(start, "malformed number"),
        }
    }

    fn literal(&mut self) -> JResult<Value> {
        let rest = &self.bytes[self.pos..];
        for (word, value) in [
            (&b"true"[..], Value::Bool(true)),
            (b"false", Value::Bool(false)),
            (b"null", Value::Null),
        ] {
            if rest.starts_with(word) {
                self.pos += word.len();
                return Ok(value);
            }
        }
        if rest.len() < 5
            && [&b"true"[..], b"false", b"null"]
                .iter()
                .any(|w| w.starts_with(rest))
        {
            return self.eof("a literal");
        }
        self.err(self.pos, "expected a value")
    }

    /// Reads one value into a tree (small documents only).
    pub fn node(&mut self) -> JResult<Node> {
        self.node_at(0)
    }

    fn node_at(&mut self, depth: usize) -> JResult<Node> {
        if depth > MAX_DEPTH {
            return self.err(self.pos, "nesting too deep");
        }
        let at = match self.peek() {
            Some(_) => self.pos,
            None => return self.eof("a value"),
        };
        let value = match self.bytes[at] {
            b'{' => {
                let mut members = Vec::new();
                self.object::<JsonError>("an object", |r, key, _| {
                    let v = r.node_at(depth + 1)?;
                    members.push((key.into_owned(), v));
                    Ok(())
                })?;
                Value::Obj(members)
            }
            b'[' => {
                let mut items = Vec::new();
                self.array::<JsonError>("an array", |r, _| {
                    items.push(r.node_at(depth + 1)?);
                    Ok(())
                })?;
                Value::Arr(items)
            }
            b'"' => Value::Str(self.string()?.into_owned()),
            b't' | b'f' | b'n' => self.literal()?,
            _ => Value::Num(self.number()?),
        };
        Ok(Node { at, value })
    }

    /// An array of exactly `N` numbers (a matrix, a point).
    pub fn numbers<const N: usize>(&mut self, what: &str) -> JResult<[f64; N]> {
        let at = self.offset();
        let mut out = [0.0; N];
        let mut n = 0;
        self.array::<JsonError>(what, |r, i| {
            let v = r.number()?;
            if i < N {
                out[i] = v;
            }
            n = i + 1;
            Ok(())
        })?;
        if n != N {
            return self.err(at, format!("{what} has {n} numbers, not {N}"));
        }
        Ok(out)
    }
}

fn printable(b: u8) -> String {
    if b.is_ascii_graphic() {
        (b as char).to_string()
    } else {
        format!("\\x{b:02x}")
    }
}

#[cfg(test)]
mod tests;
