use super::*;

fn kinds(src: &str) -> Vec<(TokenKind, String, u32, u32)> {
    let mut lx = Lexer::new(src.as_bytes(), FileId(0));
    let mut out = Vec::new();
    while let Some(t) = lx.next_token().unwrap() {
        out.push((
            t.kind,
            String::from_utf8_lossy(t.bytes).into_owned(),
            t.loc.line,
            t.loc.column,
        ));
    }
    out
}

#[test]
fn tokens_with_positions() {
    let toks = kinds("Shape \"sphere\" # c\n  \"float radius\" [ 2.5 ]");
    assert_eq!(
        toks,
        vec![
            (TokenKind::Word, "Shape".into(), 1, 1),
            (TokenKind::String, "sphere".into(), 1, 7),
            (TokenKind::String, "float radius".into(), 2, 3),
            (TokenKind::Open, "[".into(), 2, 18),
            (TokenKind::Word, "2.5".into(), 2, 20),
            (TokenKind::Close, "]".into(), 2, 24),
        ]
    );
}

#[test]
fn word_ends_at_bracket_and_quote() {
    let toks = kinds("[1 2]\"a\"x#c");
    let words: Vec<_> = toks.iter().map(|t| t.1.as_str()).collect();
    assert_eq!(words, ["[", "1", "2", "]", "a", "x"]);
}

#[test]
fn escapes() {
    let mut lx = Lexer::new(br#""a\"b\\c\n""#, FileId(0));
    let t = lx.next_token().unwrap().unwrap();
    assert_eq!(t.unescaped().unwrap(), "a\"b\\c\n");
}

#[test]
fn unterminated_string_is_error() {
    let mut lx = Lexer::new(b"  \"abc\n\"", FileId(0));
    let e = lx.next_token().unwrap_err();
    assert_eq!(e.kind, LexErrorKind::UnterminatedString);
    assert_eq!((e.loc.line, e.loc.column), (1, 3));
    let mut lx = Lexer::new(b"\"abc\\", FileId(0));
    assert!(lx.next_token().is_err());
}

#[test]
fn float_array_fast_path() {
    let mut lx = Lexer::new(b" 1 -2.5 +3e2 .5\n 1e-3 ] x", FileId(0));
    let mut v = Vec::new();
    lx.read_f32_array(&mut v).unwrap();
    assert_eq!(v, vec![1.0, -2.5, 300.0, 0.5, 0.001]);
    assert_eq!(lx.next_token().unwrap().unwrap().loc.line, 2);
}

#[test]
fn float_array_errors() {
    let mut lx = Lexer::new(b" 1 2x ]", FileId(0));
    let e = lx.read_f32_array(&mut Vec::new()).unwrap_err();
    assert_eq!(
        (e.kind, e.loc.column, e.token.as_str()),
        (LexErrorKind::ExpectedNumber, 4, "2x ]")
    );
    let mut lx = Lexer::new(b" 1 2", FileId(0));
    assert_eq!(
        lx.read_f32_array(&mut Vec::new()).unwrap_err().kind,
        LexErrorKind::UnterminatedArray
    );
}

#[test]
fn int_arrays() {
    let mut lx = Lexer::new(b"0 1 2.0 4294967295 ]", FileId(0));
    let mut v = Vec::new();
    lx.read_u32_array(&mut v).unwrap();
    assert_eq!(v, vec![0, 1, 2, u32::MAX]);
    let mut lx = Lexer::new(b"0 -1 ]", FileId(0));
    assert_eq!(
        lx.read_u32_array(&mut Vec::new()).unwrap_err().kind,
        LexErrorKind::BadInteger
    );
    let mut lx = Lexer::new(b"1.5 ]", FileId(0));
    assert_eq!(
        lx.read_i32_array(&mut Vec::new()).unwrap_err().kind,
        LexErrorKind::BadInteger
    );
    let mut lx = Lexer::new(b"-7 99999999999999999999 ]", FileId(0));
    assert!(lx.read_i32_array(&mut Vec::new()).is_err());
}

#[test]
fn count_matches_next() {
    let src = b"A [1 2 3] \"s\" # x\nB";
    assert_eq!(Lexer::new(src, FileId(0)).count_tokens().unwrap(), 8);
}

/// The fast decimal path agrees with the general parser.
mod simple_decimal {
    use super::*;
    use proptest::prelude::*;

    fn general(text: &str) -> Option<f64> {
        parse_f64(text.as_bytes())
    }

    #[test]
    fn simple_decimal_matches_the_general_parser() {
        for text in [
            "0",
            "-0",
            "+1",
            "1.",
            ".5",
            "-.5",
            "28.5746002",
            "0.7339349",
            "-0.0176519",
            "123456789012345",
            "0.000000000000000000001",
            "9007199254740991",
            "1e5",
            "1.5e-3",
            "0.1",
            "0.3",
            "1234567.890123",
        ] {
            let fast = simple_decimal(text.as_bytes(), 0).map(|(v, _)| v);
            if let Some(v) = fast {
                assert_eq!(Some(v.to_bits()), general(text).map(f64::to_bits), "{text}");
            }
        }
        // Exponents, long mantissas and words go to the general parser.
        for text in [
            "1e5",
            "12345678901234567890",
            "9007199254740993",
            "inf",
            "nan",
            "1.2.3",
            "-",
            ".",
        ] {
            assert_eq!(simple_decimal(text.as_bytes(), 0), None, "{text}");
        }
    }

    proptest! {
        #[test]
        fn simple_decimal_is_exact(int in 0u64..10_000_000, frac in 0u64..100_000_000, zeros in 0usize..6, neg: bool) {
            let text = format!("{}{int}.{}{frac}", if neg { "-" } else { "" }, "0".repeat(zeros));
            match simple_decimal(text.as_bytes(), 0) {
                Some((v, end)) => {
                    prop_assert_eq!(end, text.len());
                    prop_assert_eq!(Some(v.to_bits()), general(&text).map(f64::to_bits));
                }
                // Only mantissas past 15 digits may leave the fast path.
                None => prop_assert!(text.bytes().filter(u8::is_ascii_digit).count() > 15),
            }
        }
    }
}
