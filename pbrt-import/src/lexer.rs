//! Zero-copy tokenizer for pbrt scene text.
//!
//! Tokens borrow from the input bytes; nothing is allocated per token. Large
//! numeric arrays are read straight into `Vec<f32>`/`Vec<u32>` by
//! [`Lexer::read_f32_array`] / [`Lexer::read_u32_array`] without creating
//! tokens at all, which is what keeps multi-hundred-MB inline `trianglemesh`
//! files fast.

use std::borrow::Cow;

use crate::FileId;

mod blocks;

/// Token category.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TokenKind {
    /// A bare word: a directive name, `true`/`false`, or a number.
    Word,
    /// A quoted string; [`Token::bytes`] excludes the quotes, escapes are raw.
    String,
    /// `[`
    Open,
    /// `]`
    Close,
}

/// Where a token starts: file, 1-based line and 1-based byte column.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Loc {
    /// File the token came from (see [`crate::ParseStats::files`]).
    pub file: FileId,
    /// 1-based line.
    pub line: u32,
    /// 1-based column, counted in bytes.
    pub column: u32,
}

/// One token, borrowing its text from the input.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Token<'a> {
    /// Token category.
    pub kind: TokenKind,
    /// Raw text (for strings: between the quotes, escapes not yet applied).
    pub bytes: &'a [u8],
    /// Start position.
    pub loc: Loc,
}

impl<'a> Token<'a> {
    /// Text for error messages (lossy, quoted strings re-quoted).
    pub fn display(&self) -> String {
        let text = String::from_utf8_lossy(&self.bytes[..self.bytes.len().min(64)]);
        match self.kind {
            TokenKind::String => format!("\"{text}\""),
            _ => text.into_owned(),
        }
    }

    /// String contents with escapes applied; `None` when not valid UTF-8.
    pub fn unescaped(&self) -> Option<Cow<'a, str>> {
        if !self.bytes.contains(&b'\\') {
            return std::str::from_utf8(self.bytes).ok().map(Cow::Borrowed);
        }
        let mut out = Vec::with_capacity(self.bytes.len());
        let mut it = self.bytes.iter();
        while let Some(&b) = it.next() {
            if b != b'\\' {
                out.push(b);
                continue;
            }
            match it.next() {
                Some(b'n') => out.push(b'\n'),
                Some(b't') => out.push(b'\t'),
                Some(b'r') => out.push(b'\r'),
                Some(b'b') => out.push(8),
                Some(b'f') => out.push(12),
                Some(&c) => out.push(c),
                None => out.push(b'\\'),
            }
        }
        String::from_utf8(out).ok().map(Cow::Owned)
    }

    /// Parse as a number (bare words only).
    pub fn as_f64(&self) -> Option<f64> {
        if self.kind != TokenKind::Word {
            return None;
        }
        parse_f64(self.bytes)
    }
}

/// Tokenizer failures; the parser turns them into located errors.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LexErrorKind {
    /// A string ran into a newline or the end of input.
    UnterminatedString,
    /// A numeric array held something that is not a number.
    ExpectedNumber,
    /// A numeric array ended without `]`.
    UnterminatedArray,
    /// An integer array element is negative, fractional or too large.
    BadInteger,
}

/// Lexer error with its position and the offending text.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LexError {
    /// What went wrong.
    pub kind: LexErrorKind,
    /// Where.
    pub loc: Loc,
    /// Offending text (truncated).
    pub token: String,
}

// Byte classes: 1 = whitespace, 2 = delimiter that ends a word (`"[]#`), 0 = word byte.
const CLASS: [u8; 256] = {
    let mut t = [0u8; 256];
    t[b' ' as usize] = 1;
    t[b'\t' as usize] = 1;
    t[b'\r' as usize] = 1;
    t[b'\n' as usize] = 1;
    t[0x0b] = 1;
    t[0x0c] = 1;
    t[b'"' as usize] = 2;
    t[b'[' as usize] = 2;
    t[b']' as usize] = 2;
    t[b'#' as usize] = 2;
    t
};

#[inline]
fn is_word_end(b: u8) -> bool {
    CLASS[b as usize] != 0
}

/// Whether `b` ends a bare word (whitespace, `"`, `[`, `]`, `#`).
#[inline]
pub(crate) fn is_word_end_byte(b: u8) -> bool {
    is_word_end(b)
}

/// Parse a bare number as f64 (whole slice must be consumed).
pub fn parse_f64(bytes: &[u8]) -> Option<f64> {
    let b = bytes.strip_prefix(b"+").unwrap_or(bytes);
    match fast_float2::parse_partial::<f64, _>(b) {
        Ok((v, n)) if n == b.len() && n > 0 => Some(v),
        _ => None,
    }
}

/// Exact powers of ten (every one up to 1e22 is representable in f64).
const POW10: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];

/// Exact `f32` powers of ten (every one up to 1e10 is representable in f32).
const POW10_F32: [f32; 8] = [1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7];

/// Powers of ten as integers, for joining integer and fraction digits.
const POW10_U64: [u64; 8] = [1, 10, 100, 1_000, 10_000, 100_000, 1_000_000, 10_000_000];

/// The value of eight decimal digits held one per byte (`0..=9`, first digit in the lowest
/// byte), by three multiplications instead of eight (the SWAR reduction `fast_float` uses).
#[inline]
fn eight_digits(v: u64) -> u32 {
    const MASK: u64 = 0x0000_00FF_0000_00FF;
    const MUL1: u64 = 0x000F_4240_0000_0064; // 100 + (1_000_000 << 32)
    const MUL2: u64 = 0x0000_2710_0000_0001; // 1 + (10_000 << 32)
    let v = v.wrapping_mul(10).wrapping_add(v >> 8);
    let v = (v & MASK)
        .wrapping_mul(MUL1)
        .wrapping_add(((v >> 16) & MASK).wrapping_mul(MUL2))
        >> 32;
    v as u32
}

/// The run of 1 to 7 decimal digits that starts `bytes[start..]`, read as one 8-byte word:
/// its value and length. `None` when fewer than 8 bytes remain, when the run is empty or
/// when it is 8 digits or longer (the scalar parsers take those).
#[inline]
fn digit_run(bytes: &[u8], start: usize) -> Option<(u32, usize)> {
    let word = u64::from_le_bytes(bytes.get(start..start + 8)?.try_into().ok()?);
    let val = word.wrapping_sub(0x3030_3030_3030_3030);
    // A byte's high bit is set here iff it is not an ASCII digit; bytes after the first
    // non-digit may be garbled by borrows and carries, but only the first one is used.
    let non_digit = (word.wrapping_add(0x4646_4646_4646_4646) | val) & 0x8080_8080_8080_8080;
    let n = (non_digit.trailing_zeros() / 8) as usize;
    if n == 0 || n == 8 {
        return None;
    }
    // Shifting the digits to the top leaves leading zero digits below them.
    Some((eight_digits(val << (8 * (8 - n))), n))
}

/// A non-negative integer of 1 to 7 digits ending at a word end (mesh indices), 8 bytes at a
/// time: its value and end offset. `None` sends the caller to the scalar parser.
#[inline]
fn word_uint(bytes: &[u8], start: usize) -> Option<(u32, usize)> {
    let (v, n) = digit_run(bytes, start)?;
    // `n < 8`, so the byte after the digits is inside the word read.
    is_word_end(bytes[start + n]).then_some((v, start + n))
}

/// `-?digits[.digits]` with 1 to 7 digits on each side of the point, ending at a word end,
/// read 8 bytes at a time: (negative, all digits as one integer, fraction digits, end).
/// `None` (signs `+`, exponents, long runs, a point without digits after it, ...) sends the
/// caller to the general parsers.
#[inline]
fn word_decimal(bytes: &[u8], start: usize) -> Option<(bool, u64, usize, usize)> {
    let neg = bytes.get(start) == Some(&b'-');
    let mut p = start + usize::from(neg);
    let (int, n) = digit_run(bytes, p)?;
    p += n;
    let (m, k) = if bytes[p] == b'.' {
        p += 1;
        let (frac, k) = digit_run(bytes, p)?;
        p += k;
        (u64::from(int) * POW10_U64[k] + u64::from(frac), k)
    } else {
        (u64::from(int), 0)
    };
    // The byte after the digits is inside the last word read.
    is_word_end(bytes[p]).then_some((neg, m, k, p))
}

/// [`word_decimal`] as `f32`: when the digits form an integer `m < 2^24` and there are
/// `k <= 7` fraction digits, `m` and `10^k` are exact in `f32` and `m / 10^k` is one
/// correctly rounded division (Clinger's fast path in single precision), so the result
/// equals `fast_float`'s.
#[inline]
fn word_f32(bytes: &[u8], start: usize) -> Option<(f32, usize)> {
    let (neg, m, k, end) = word_decimal(bytes, start)?;
    if m >= 1 << 24 {
        return None;
    }
    let v = m as f32 / POW10_F32[k];
    Some((if neg { -v } else { v }, end))
}

/// Fast path for the plain decimals that dominate scene text (`-12.5`, `0.7339349`, `1`):
/// `[+-]?digits[.digits]` ending at a word end, at most 19 digits in all. When the digits
/// form an integer `m < 2^53` and there are `k <= 22` fraction digits, `m` and `10^k` are
/// exact and `m / 10^k` is one correctly rounded IEEE division (Clinger's fast path), so
/// the result equals `fast_float`'s. Returns the value and the end offset; `None` sends
/// the caller to the general parser.
#[inline]
fn simple_decimal(bytes: &[u8], start: usize) -> Option<(f64, usize)> {
    if let Some((neg, m, k, end)) = word_decimal(bytes, start) {
        // At most 14 digits: `m < 2^53`.
        let v = m as f64 / POW10[k];
        return Some((if neg { -v } else { v }, end));
    }
    let s = bytes.get(start..)?;
    let (neg, mut i) = match s.first() {
        Some(b'-') => (true, 1),
        Some(b'+') => (false, 1),
        _ => (false, 0),
    };
    let mut m: u64 = 0;
    let int_start = i;
    while i < s.len() {
        let d = s[i].wrapping_sub(b'0');
        if d > 9 {
            break;
        }
        m = m.wrapping_mul(10).wrapping_add(u64::from(d));
        i += 1;
    }
    let int_digits = i - int_start;
    let mut frac_digits = 0;
    if s.get(i) == Some(&b'.') {
        i += 1;
        let frac_start = i;
        while i < s.len() {
            let d = s[i].wrapping_sub(b'0');
            if d > 9 {
                break;
            }
            m = m.wrapping_mul(10).wrapping_add(u64::from(d));
            i += 1;
        }
        frac_digits = i - frac_start;
    }
    // At most 19 digits cannot wrap a u64; `m < 2^53` is exact in f64.
    if int_digits + frac_digits == 0 || int_digits + frac_digits > 19 || frac_digits > 22 {
        return None;
    }
    if m >= 1 << 53 || s.get(i).is_some_and(|&c| !is_word_end(c)) {
        return None; // long mantissa, exponent, `inf`, garbage: the general parser decides
    }
    let v = m as f64 / POW10[frac_digits];
    Some((if neg { -v } else { v }, start + i))
}

/// Streaming tokenizer over one file's bytes.
#[derive(Clone)]
pub struct Lexer<'a> {
    bytes: &'a [u8],
    pos: usize,
    line: u32,
    line_start: usize,
    file: FileId,
}

impl<'a> Lexer<'a> {
    /// Tokenize `bytes`, reporting positions in `file`.
    pub fn new(bytes: &'a [u8], file: FileId) -> Self {
        // A UTF-8 byte order mark is not part of the scene.
        let pos = if bytes.starts_with(&[0xef, 0xbb, 0xbf]) {
            3
        } else {
            0
        };
        Lexer {
            bytes,
            pos,
            line: 1,
            line_start: pos,
            file,
        }
    }

    /// Byte offset of the next unread byte.
    pub fn offset(&self) -> usize {
        self.pos
    }

    /// Current position (after skipping nothing).
    pub fn loc(&self) -> Loc {
        Loc {
            file: self.file,
            line: self.line,
            column: (self.pos - self.line_start + 1) as u32,
        }
    }

    fn error(&self, kind: LexErrorKind, start: usize, loc: Loc) -> LexError {
        let end = (start + 32).min(self.bytes.len());
        let mut stop = start;
        while stop < end && !matches!(self.bytes[stop], b'\n' | b'\r') {
            stop += 1;
        }
        LexError {
            kind,
            loc,
            token: String::from_utf8_lossy(&self.bytes[start..stop]).into_owned(),
        }
    }

    /// Skip whitespace and comments, counting lines.
    #[inline]
    fn skip_ws(&mut self) {
        let bytes = self.bytes;
        let mut pos = self.pos;
        while pos < bytes.len() {
            let b = bytes[pos];
            if b == b'\n' {
                pos += 1;
                self.line += 1;
                self.line_start = pos;
            } else if CLASS[b as usize] == 1 {
                pos += 1;
            } else if b == b'#' {
                // Comments run to the end of the line; the newline is counted above.
                pos += bytes[pos..]
                    .iter()
                    .position(|&c| c == b'\n')
                    .unwrap_or(bytes.len() - pos);
            } else {
                break;
            }
        }
        self.pos = pos;
    }

    /// Next token, `Ok(None)` at end of input.
    #[inline]
    pub fn next_token(&mut self) -> Result<Option<Token<'a>>, LexError> {
        self.skip_ws();
        let bytes = self.bytes;
        let start = self.pos;
        let Some(&b) = bytes.get(start) else {
            return Ok(None);
        };
        let loc = self.loc();
        let (kind, text) = match b {
            b'[' => {
                self.pos += 1;
                (TokenKind::Open, &bytes[start..start + 1])
            }
            b']' => {
                self.pos += 1;
                (TokenKind::Close, &bytes[start..start + 1])
            }
            b'"' => {
                let mut p = start + 1;
                loop {
                    match bytes.get(p) {
                        None | Some(b'\n') => {
                            return Err(self.error(LexErrorKind::UnterminatedString, start, loc));
                        }
                        Some(b'"') => break,
                        Some(b'\\') => p += 2,
                        Some(_) => p += 1,
                    }
                }
                if p >= bytes.len() {
                    return Err(self.error(LexErrorKind::UnterminatedString, start, loc));
                }
                self.pos = p + 1;
                (TokenKind::String, &bytes[start + 1..p])
            }
            _ => {
                let mut p = start + 1;
                while p < bytes.len() && !is_word_end(bytes[p]) {
                    p += 1;
                }
                self.pos = p;
                (TokenKind::Word, &bytes[start..p])
            }
        };
        Ok(Some(Token {
            kind,
            bytes: text,
            loc,
        }))
    }

    /// Look at the next token without consuming it.
    pub fn peek_token(&mut self) -> Result<Option<Token<'a>>, LexError> {
        let saved = self.clone();
        let t = self.next_token();
        *self = saved;
        t
    }

    /// Kind of the next token without consuming anything but whitespace.
    pub fn peek_byte(&mut self) -> Option<u8> {
        self.skip_ws();
        self.bytes.get(self.pos).copied()
    }

    /// Read numbers until `]` (consumed) into `out`; the `[` must already be consumed.
    ///
    /// Hot path for mesh arrays: no tokens, one pass, fast float parsing.
    pub fn read_f32_array(&mut self, out: &mut Vec<f32>) -> Result<(), LexError> {
        loop {
            self.array_run(out, word_f32, |lx, at| lx.read_f32_at(at).ok());
            // Where the run stopped (`]`, a comment, the input's last bytes, an error): one
            // step of the general reader, which reports errors with their positions.
            self.skip_ws();
            let start = self.pos;
            let Some(&b) = self.bytes.get(start) else {
                let loc = self.loc();
                return Err(self.error(LexErrorKind::UnterminatedArray, start, loc));
            };
            if b == b']' {
                self.pos += 1;
                return Ok(());
            }
            let v = self.read_f32_at(start)?;
            out.push(v);
        }
    }

    #[inline]
    fn read_f32_at(&mut self, start: usize) -> Result<f32, LexError> {
        if let Some((v, end)) = word_f32(self.bytes, start) {
            self.pos = end;
            return Ok(v);
        }
        let rest = &self.bytes[start..];
        let (skip, rest) = match rest.first() {
            Some(b'+') => (1, &rest[1..]),
            _ => (0, rest),
        };
        match fast_float2::parse_partial::<f32, _>(rest) {
            Ok((v, n)) if n > 0 && rest.get(n).is_none_or(|&c| is_word_end(c)) => {
                self.pos = start + skip + n;
                Ok(v)
            }
            _ => {
                let loc = self.loc();
                Err(self.error(LexErrorKind::ExpectedNumber, start, loc))
            }
        }
    }

    /// Read one bare number as f64 (directive arguments such as `Transform`'s 16 values).
    /// `None` when the next token is not a number (nothing consumed but whitespace).
    #[inline]
    pub fn read_f64(&mut self) -> Option<f64> {
        self.skip_ws();
        let start = self.pos;
        if let Some((v, end)) = simple_decimal(self.bytes, start) {
            self.pos = end;
            return Some(v);
        }
        let rest = &self.bytes[start..];
        let (skip, rest) = match rest.first() {
            Some(b'+') => (1, &rest[1..]),
            _ => (0, rest),
        };
        match fast_float2::parse_partial::<f64, _>(rest) {
            Ok((v, n)) if n > 0 && rest.get(n).is_none_or(|&c| is_word_end(c)) => {
                self.pos = start + skip + n;
                Some(v)
            }
            _ => None,
        }
    }

    /// Read non-negative integers until `]` (consumed) into `out`.
    pub fn read_u32_array(&mut self, out: &mut Vec<u32>) -> Result<(), LexError> {
        self.read_int_array(out)
    }

    /// Read integers until `]` (consumed) into `out`.
    pub fn read_i32_array(&mut self, out: &mut Vec<i32>) -> Result<(), LexError> {
        self.read_int_array(out)
    }

    /// Read integers that fit `T` until `]` (consumed) into `out`; one out of range is an error
    /// at its position.
    fn read_int_array<T: TryFrom<i64>>(&mut self, out: &mut Vec<T>) -> Result<(), LexError> {
        loop {
            self.array_run(
                out,
                |bytes, at| {
                    let (v, end) = word_uint(bytes, at)?;
                    Some((T::try_from(i64::from(v)).ok()?, end))
                },
                |lx, at| T::try_from(lx.read_i64_at(at).ok()?).ok(),
            );
            // As in `read_f32_array`: one general step where the run stopped.
            self.skip_ws();
            let start = self.pos;
            let Some(&b) = self.bytes.get(start) else {
                let loc = self.loc();
                return Err(self.error(LexErrorKind::UnterminatedArray, start, loc));
            };
            if b == b']' {
                self.pos += 1;
                return Ok(());
            }
            let v = match word_uint(self.bytes, start) {
                Some((v, end)) => {
                    self.pos = end;
                    i64::from(v)
                }
                None => self.read_i64_at(start)?,
            };
            match T::try_from(v) {
                Ok(v) => out.push(v),
                Err(_) => {
                    self.pos = start;
                    let loc = self.loc();
                    return Err(self.error(LexErrorKind::BadInteger, start, loc));
                }
            }
        }
    }

    /// One integer; accepts integral floats like `3.0` (some exporters write them).
    #[inline]
    fn read_i64_at(&mut self, start: usize) -> Result<i64, LexError> {
        let bytes = self.bytes;
        let mut p = start;
        let neg = match bytes.get(p) {
            Some(b'-') => {
                p += 1;
                true
            }
            Some(b'+') => {
                p += 1;
                false
            }
            _ => false,
        };
        let digits_start = p;
        let mut v: i64 = 0;
        while let Some(&c) = bytes.get(p) {
            if !c.is_ascii_digit() || p - digits_start >= 18 {
                break;
            }
            v = v * 10 + i64::from(c - b'0');
            p += 1;
        }
        if p > digits_start && bytes.get(p).is_none_or(|&c| is_word_end(c)) {
            self.pos = p;
            return Ok(if neg { -v } else { v });
        }
        // Slow path: `3.0`, `1e2`.
        let loc = self.loc();
        let mut end = start;
        while end < bytes.len() && !is_word_end(bytes[end]) {
            end += 1;
        }
        match parse_f64(&bytes[start..end]) {
            Some(f) if f.fract() == 0.0 && f.abs() < 9.0e15 => {
                self.pos = end;
                Ok(f as i64)
            }
            Some(_) => Err(self.error(LexErrorKind::BadInteger, start, loc)),
            None => Err(self.error(LexErrorKind::ExpectedNumber, start, loc)),
        }
    }

    /// Count all tokens to the end (benchmark helper; equivalent to draining `next_token`).
    pub fn count_tokens(mut self) -> Result<u64, LexError> {
        let mut n = 0;
        while self.next_token()?.is_some() {
            n += 1;
        }
        Ok(n)
    }
}

#[cfg(test)]
mod tests;
