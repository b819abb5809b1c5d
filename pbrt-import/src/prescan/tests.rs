use super::*;
use crate::lexer::{Lexer, TokenKind};
use crate::FileId;

/// The token-based definition the byte scanner must agree with.
fn reference(bytes: &[u8]) -> bool {
    let mut lx = Lexer::new(bytes, FileId(0));
    while let Ok(Some(t)) = lx.next_token() {
        match t.kind {
            TokenKind::Word if V4_DIRECTIVES.contains(&t.bytes) => return true,
            TokenKind::String
                if V4_NAMES.contains(&t.bytes)
                    || V4_TYPE_PREFIXES.iter().any(|p| t.bytes.starts_with(p)) =>
            {
                return true
            }
            _ => {}
        }
    }
    false
}

#[test]
fn mentions_include_finds_the_word_at_any_offset() {
    for pad in 0..20 {
        for word in ["Include", "Import"] {
            let text = format!("{}{word} \"x\"", "1 ".repeat(pad));
            assert!(mentions_include(text.as_bytes()), "{text}");
            // Straddling the end of the buffer.
            assert!(mentions_include(&text.as_bytes()[..pad * 2 + word.len()]));
        }
        let text = format!("{}Incl Impor IInclud", "0 ".repeat(pad));
        assert!(!mentions_include(text.as_bytes()), "{text}");
    }
}

#[test]
fn swar_interesting_is_exact_per_byte() {
    for b in 0..=255u8 {
        let want = b == b'"' || b == b'#' || b.is_ascii_uppercase();
        for lane in 0..8 {
            let mut chunk = [b'0'; 8];
            chunk[lane] = b;
            assert_eq!(
                swar_interesting(u64::from_le_bytes(chunk)),
                want,
                "{b:#x} at {lane}"
            );
        }
    }
}

proptest::proptest! {
    #[test]
    fn prescan_agrees_with_the_lexer_on_token_soup(
        parts in proptest::collection::vec(
            proptest::prop_oneof![
                proptest::strategy::Just("Import".to_owned()),
                proptest::strategy::Just("Option".to_owned()),
                proptest::strategy::Just("\"point3 P\"".to_owned()),
                proptest::strategy::Just("\"conductor\"".to_owned()),
                proptest::strategy::Just("# Import\n".to_owned()),
                "[a-zA-Z0-9.\\-]{0,12}",
                "[ \n\t\"\\[\\]#]{0,2}",
            ],
            0..24,
        )
    ) {
        let text = parts.concat();
        proptest::prop_assert_eq!(prescan_is_v4(text.as_bytes()), reference(text.as_bytes()), "{}", text);
    }
}

#[test]
fn prescan_matches_the_token_definition() {
    let cases: &[&str] = &[
        "WorldBegin Shape \"sphere\"",
        "WorldBegin Import \"x.pbrt\"",
        "# Import \"x\"\nShape \"sphere\"",
        "Shape \"trianglemesh\" \"point3 P\" [0 0 0]",
        "Shape \"trianglemesh\" \"point P\" [0 0 0]",
        "Translate 1E5 2 3 Attribute \"shape\"",
        "Material \"coateddiffuse\"",
        "Texture \"a\" \"color\" \"imagemap\" \"string filename\" \"Import\"",
        "ColorSpaceX 1",
        "Transform [ 1 0 0 0 0 1 0 0 0 0 1 0 10.1657 2.08030009 28.5746002 1 ] Option 1",
        "1234567812345678Option",
        "x abcdefghImport 1",
        "1 abcdefgImport 1",
        "0.5 0.25 0.125 0.0625 abcdefghijklmnopOption Import",
        "\"unterminated\nOption",
    ];
    for case in cases {
        assert_eq!(
            prescan_is_v4(case.as_bytes()),
            reference(case.as_bytes()),
            "{case}"
        );
    }
}

/// The one-pass search answers as the two substring searches it replaced, on texts made of
/// pieces of the words (near misses everywhere, words at both ends).
#[test]
fn mentions_include_is_the_two_substring_searches() {
    let pieces: [&[u8]; 10] = [
        b"I", b"In", b"Incl", b"Include", b"Import", b"Impor", b"nclude", b"mport", b" ", b"x",
    ];
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut found = 0;
    for n in 0..20_000usize {
        let mut text = Vec::new();
        for _ in 0..n % 12 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            text.extend_from_slice(pieces[(state % pieces.len() as u64) as usize]);
        }
        let want = memchr::memmem::find(&text, b"Include").is_some()
            || memchr::memmem::find(&text, b"Import").is_some();
        found += usize::from(want);
        assert_eq!(
            mentions_include(&text),
            want,
            "{}",
            String::from_utf8_lossy(&text)
        );
    }
    // Both answers occur often.
    assert!((2_000..18_000).contains(&found), "{found}");
}
