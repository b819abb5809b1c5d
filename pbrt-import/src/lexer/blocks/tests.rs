//! The block reader against the general reader it shortcuts: same values (bits), same
//! position, line and column afterwards, same errors.

use proptest::prelude::*;

use super::super::{LexError, LexErrorKind, Lexer};
use crate::FileId;

/// The array readers as they were before the block reader: a general step per number.
fn general_f32(lx: &mut Lexer<'_>, out: &mut Vec<f32>) -> Result<(), LexError> {
    loop {
        lx.skip_ws();
        let start = lx.pos;
        let Some(&b) = lx.bytes.get(start) else {
            let loc = lx.loc();
            return Err(lx.error(LexErrorKind::UnterminatedArray, start, loc));
        };
        if b == b']' {
            lx.pos += 1;
            return Ok(());
        }
        let v = lx.read_f32_at(start)?;
        out.push(v);
    }
}

fn general_int<T: TryFrom<i64>>(lx: &mut Lexer<'_>, out: &mut Vec<T>) -> Result<(), LexError> {
    loop {
        lx.skip_ws();
        let start = lx.pos;
        let Some(&b) = lx.bytes.get(start) else {
            let loc = lx.loc();
            return Err(lx.error(LexErrorKind::UnterminatedArray, start, loc));
        };
        if b == b']' {
            lx.pos += 1;
            return Ok(());
        }
        let v = lx.read_i64_at(start)?;
        match T::try_from(v) {
            Ok(v) => out.push(v),
            Err(_) => {
                lx.pos = start;
                let loc = lx.loc();
                return Err(lx.error(LexErrorKind::BadInteger, start, loc));
            }
        }
    }
}

/// What a read left behind: the result, the values and where the lexer stands.
type Outcome = (Result<(), LexError>, Vec<u32>, usize, u32, u32);

fn outcome<T: Copy>(
    text: &[u8],
    read: impl FnOnce(&mut Lexer<'_>, &mut Vec<T>) -> Result<(), LexError>,
    bits: impl Fn(T) -> u32,
) -> Outcome {
    let mut lx = Lexer::new(text, FileId(0));
    let mut out = Vec::new();
    let r = read(&mut lx, &mut out);
    let loc = lx.loc();
    (
        r,
        out.into_iter().map(bits).collect(),
        lx.offset(),
        loc.line,
        loc.column,
    )
}

fn assert_same(text: &[u8]) {
    let shown = String::from_utf8_lossy(text);
    let f = |v: f32| v.to_bits();
    assert_eq!(
        outcome(text, |lx, o| lx.read_f32_array(o), f),
        outcome(text, general_f32, f),
        "f32: {shown:?}"
    );
    assert_eq!(
        outcome(
            text,
            |lx, o: &mut Vec<i32>| lx.read_i32_array(o),
            |v| v as u32
        ),
        outcome(text, general_int::<i32>, |v| v as u32),
        "i32: {shown:?}"
    );
    assert_eq!(
        outcome(text, |lx, o: &mut Vec<u32>| lx.read_u32_array(o), |v| v),
        outcome(text, general_int::<u32>, |v| v),
        "u32: {shown:?}"
    );
}

/// Words: the numbers the 8-byte parsers take, the ones only the general reader takes
/// (signs, exponents, long runs, `-0`, overflow), and words that end a run or are errors.
const WORDS: &[&str] = &[
    "0",
    "7",
    "190",
    "1234567",
    "12345678",
    "4294967296",
    "-5",
    "+3",
    "-0",
    "3.0",
    "1e2",
    "-1196.809",
    "0.7339349",
    "0.73393491",
    "-0.0000001",
    "1e39",
    "1e-46",
    "-1e-46",
    ".5",
    "5.",
    "3.5e-3",
    "16777217",
    "123456789012345678901234567890",
    "x",
    "1x",
    "]",
    "#c\n",
    "\"s\"",
    "[",
];
const BLANKS: &[&str] = &[
    " ", " ", " ", "    ", "\n", "\n    ", "\t", "\r\n", "\x0b", "\x0c",
];

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]
    #[test]
    fn blocks_read_as_the_general_reader(
        lead in 0usize..9,
        parts in prop::collection::vec((0usize..60, 0usize..BLANKS.len()), 0..120),
        close in any::<bool>(),
    ) {
        let mut text = " ".repeat(lead);
        for (w, b) in parts {
            // Mostly plain numbers, the way meshes are written.
            text.push_str(if w < WORDS.len() { WORDS[w] } else { WORDS[(w * 7) % 12] });
            text.push_str(BLANKS[b]);
        }
        if close {
            text.push_str("] Shape");
        }
        assert_same(text.as_bytes());
    }
}

#[test]
fn long_plain_arrays_cross_blocks_with_lines_counted() {
    let mut text = String::new();
    for i in 0..5000u32 {
        text.push_str(&format!("{} -{}.{} ", i % 977, i % 313, i % 97));
        if i % 7 == 6 {
            text.push_str("\n  ");
        }
    }
    text.push_str("\n ]");
    assert_same(text.as_bytes());
    // An error far in: reported where the general reader reports it.
    let at = text.len() * 3 / 4;
    let at = at + text[at..].find(' ').unwrap_or(0) + 1;
    let bad = format!("{}1x2 {}", &text[..at], &text[at..]);
    assert_same(bad.as_bytes());
    let mut lx = Lexer::new(bad.as_bytes(), FileId(0));
    let e = lx.read_f32_array(&mut Vec::new()).unwrap_err();
    assert_eq!(e.kind, LexErrorKind::ExpectedNumber);
    let line = 1 + bad[..at].matches('\n').count() as u32;
    assert_eq!(e.loc.line, line, "{:?}", e.loc);
}
