//! Byte scanners that look at a file before it is parsed: does it use pbrt-v4 constructs,
//! does it mention `Include`/`Import` (vectorised substring searches, so number-only files cost
//! next to nothing). Used by the parser and by the parallel include workers.

use crate::lexer::is_word_end_byte;

/// v4-only material and film names; seeing one switches `Auto` to v4.
pub(crate) const V4_NAMES: &[&[u8]] = &[
    b"coateddiffuse",
    b"coatedconductor",
    b"conductor",
    b"dielectric",
    b"thindielectric",
    b"diffusetransmission",
    b"gbuffer",
    b"spectral",
    b"bilinearmesh",
];

pub(crate) const V4_DIRECTIVES: &[&[u8]] = &[b"Import", b"ColorSpace", b"Option", b"Attribute"];

/// Find pbrt-v4-only constructs in (the start of) a file.
///
/// A byte scanner rather than the lexer: it only looks at words that start with an
/// upper-case letter (directives) and at quoted strings, and skips numbers without
/// building tokens, so it costs a fraction of a parse even on instance-heavy files.
pub(crate) fn prescan_is_v4(bytes: &[u8]) -> bool {
    let bytes = &bytes[..bytes.len().min(16 << 20)];
    let mut pos = 0;
    while pos < bytes.len() {
        let b = bytes[pos];
        match b {
            b'#' => pos = line_end(bytes, pos),
            b'"' => {
                let start = pos + 1;
                let p = string_end(bytes, start);
                if p >= bytes.len() || bytes[p] == b'\n' {
                    return false; // unterminated string: the lexer stops here too
                }
                let text = &bytes[start..p];
                if V4_NAMES.contains(&text) || V4_TYPE_PREFIXES.iter().any(|t| text.starts_with(t))
                {
                    return true;
                }
                pos = p + 1;
            }
            b'A'..=b'Z' => {
                let start = pos;
                while pos < bytes.len() && !is_word_end_byte(bytes[pos]) {
                    pos += 1;
                }
                if V4_DIRECTIVES.contains(&&bytes[start..pos]) {
                    return true;
                }
            }
            _ if is_word_end_byte(b) => pos += 1,
            _ => {
                pos = skip_plain(bytes, pos);
            }
        }
    }
    false
}

/// The end of the comment or line at `pos` (its newline, or the end of `bytes`).
#[inline]
pub(crate) fn line_end(bytes: &[u8], pos: usize) -> usize {
    pos + memchr::memchr(b'\n', &bytes[pos..]).unwrap_or(bytes.len() - pos)
}

/// Where the string whose text starts at `start` ends: its closing quote, or the newline or
/// end of `bytes` that leaves it unterminated (the caller tells which). Skips `\` escapes.
#[inline]
pub(crate) fn string_end(bytes: &[u8], start: usize) -> usize {
    let mut p = start;
    while p < bytes.len() && !matches!(bytes[p], b'"' | b'\n') {
        p += if bytes[p] == b'\\' { 2 } else { 1 };
    }
    p
}

/// From inside a number or lower-case word at `pos`: skips the whole word, then every 8-byte
/// run without a quote, `#` or upper-case letter (pure numbers and whitespace), and returns
/// the next position where a string, comment or directive may start.
#[inline]
pub(crate) fn skip_plain(bytes: &[u8], mut pos: usize) -> usize {
    while pos < bytes.len() && !is_word_end_byte(bytes[pos]) {
        pos += 1;
    }
    while let Some(chunk) = bytes.get(pos..pos + 8) {
        let x = u64::from_le_bytes(chunk.try_into().unwrap_or([b'"'; 8]));
        if swar_interesting(x) {
            break;
        }
        pos += 8;
    }
    // A skip may stop inside a word (`abcdefghXyz`): finish that word, so an upper-case
    // letter is only taken for a directive at a word start.
    while pos > 0
        && pos < bytes.len()
        && !is_word_end_byte(bytes[pos - 1])
        && !is_word_end_byte(bytes[pos])
    {
        pos += 1;
    }
    pos
}

/// Whether any byte of `x` is `"`, `#` or `A`..=`Z` (exact: no false positives or negatives
/// for "any"; bytes >= 0x80 never match). Word boundaries are rechecked byte by byte.
#[inline]
pub(crate) fn swar_interesting(x: u64) -> bool {
    const LO: u64 = 0x0101_0101_0101_0101;
    const HI: u64 = 0x8080_8080_8080_8080;
    let has_zero = |v: u64| v.wrapping_sub(LO) & !v & HI != 0;
    let quote = has_zero(x ^ (LO * u64::from(b'"')));
    let hash = has_zero(x ^ (LO * u64::from(b'#')));
    // Bytes c with 'A' <= c <= 'Z': (c & 0x7f) + (0x7f - 'Z') has bit 7 clear and
    // (c & 0x7f) + (0x80 - 'A') has bit 7 set, and c itself has bit 7 clear.
    let low7 = x & (LO * 0x7f);
    let above_z = low7 + LO * u64::from(0x7f - b'Z');
    let from_a = low7 + LO * u64::from(0x80 - b'A');
    let upper = !above_z & from_a & !x & HI != 0;
    quote || hash || upper
}

/// Whether `bytes` contain `Import` or `Include` anywhere: one vectorised search for `I`
/// (`memchr`), each hit checked for the rest of either word, so the huge number-only files
/// Moana is made of cost next to nothing. (A SWAR scan for `I` did a byte-by-byte check at
/// every instance line, whose `ObjectInstance` has one; two `memmem` passes, one a word,
/// cost 358M instructions on the minipbrt set's 382 MB, 1.5% of its import.)
pub(crate) fn mentions_include(bytes: &[u8]) -> bool {
    memchr::memchr_iter(b'I', bytes).any(|i| {
        let rest = &bytes[i + 1..];
        rest.starts_with(b"nclude") || rest.starts_with(b"mport")
    })
}

/// Parameter type spellings only pbrt-v4 uses (a parameter declaration starts with one).
const V4_TYPE_PREFIXES: &[&[u8]] = &[
    b"point3 ",
    b"point2 ",
    b"normal3 ",
    b"vector3 ",
    b"vector2 ",
];

#[cfg(test)]
mod tests;
