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

/// The 8-bytes-at-a-time number paths agree with the general parsers, byte for byte.
mod word_numbers {
    use super::*;
    use proptest::prelude::*;

    /// Room after the number, so the paths that need 8 readable bytes engage.
    const PAD: &str = "        ";

    #[test]
    fn digit_runs() {
        for (text, want) in [
            ("0 ", Some((0, 1))),
            ("7]", Some((7, 1))),
            ("1234567 ", Some((1_234_567, 7))),
            ("0000042\n", Some((42, 7))),
            ("12345678", None), // 8 digits: the scalar path
            ("x1", None),
            (" 1", None),
            ("1234", None), // fewer than 8 bytes readable
        ] {
            let padded = if text.len() < 8 && text != "1234" {
                format!("{text}{PAD}")
            } else {
                text.to_string()
            };
            assert_eq!(digit_run(padded.as_bytes(), 0), want, "{text:?}");
        }
        // Any byte that is not a digit ends the run, including bytes whose arithmetic
        // carries or borrows (`/` just below `0`, `:` just above `9`, high bytes).
        for stop in [b'/', b':', b'.', 0u8, 0x7f, 0xb9, 0xba, 0xc0, 0xff] {
            let mut bytes = b"123".to_vec();
            bytes.push(stop);
            bytes.extend_from_slice(b"45678901");
            assert_eq!(digit_run(&bytes, 0), Some((123, 3)), "stop byte {stop:#x}");
        }
    }

    #[test]
    fn words_that_leave_the_fast_paths() {
        for text in [
            "+1",
            "-.5",
            ".5",
            "1.",
            "1e5",
            "1.5e-3",
            "1.2.3",
            "12a",
            "-",
            "inf",
            "0x10",
            "12345678.5",
            "1.12345678",
            "16777216.0",
            "1677.7216",
        ] {
            let padded = format!("{text}{PAD}");
            assert_eq!(word_f32(padded.as_bytes(), 0), None, "{text}");
        }
        for text in ["-1", "+1", "1.0", "1e2", "12345678", "9x"] {
            let padded = format!("{text}{PAD}");
            assert_eq!(word_uint(padded.as_bytes(), 0), None, "{text}");
        }
    }

    fn fast_float_f32(text: &str) -> Option<f32> {
        let b = text.as_bytes();
        let b = b.strip_prefix(b"+").unwrap_or(b);
        match fast_float2::parse_partial::<f32, _>(b) {
            Ok((v, n)) if n == b.len() => Some(v),
            _ => None,
        }
    }

    proptest! {
        #[test]
        fn uint_matches_str_parse(v in 0u32..100_000_000, end in prop::sample::select(vec![" ", "]", "\n", "\t", "#", "\"", "["])) {
            let text = format!("{v}{end}{PAD}");
            match word_uint(text.as_bytes(), 0) {
                Some((got, stop)) => {
                    prop_assert_eq!(got, v);
                    prop_assert_eq!(stop, v.to_string().len());
                }
                None => prop_assert!(v >= 10_000_000),
            }
        }

        #[test]
        fn f32_matches_fast_float(int in 0u64..100_000_000, frac in 0u64..100_000_000, zeros in 0usize..4, point: bool, neg: bool) {
            let sign = if neg { "-" } else { "" };
            let num = if point {
                format!("{sign}{int}.{}{frac}", "0".repeat(zeros))
            } else {
                format!("{sign}{int}")
            };
            let text = format!("{num} {PAD}");
            match word_f32(text.as_bytes(), 0) {
                Some((v, end)) => {
                    prop_assert_eq!(end, num.len());
                    prop_assert_eq!(Some(v.to_bits()), fast_float_f32(&num).map(f32::to_bits), "{}", num);
                }
                // Only long runs and mantissas of 2^24 or more leave the fast path.
                None => {
                    let digits = num.bytes().filter(u8::is_ascii_digit).count();
                    prop_assert!(digits > 7, "{}", num);
                }
            }
        }

        #[test]
        fn f64_matches_the_general_parser(int in 0u64..10_000_000, frac in 0u64..10_000_000, zeros in 0usize..3, neg: bool) {
            let num = format!("{}{int}.{}{frac}", if neg { "-" } else { "" }, "0".repeat(zeros));
            let text = format!("{num}]{PAD}");
            match simple_decimal(text.as_bytes(), 0) {
                Some((v, end)) => {
                    prop_assert_eq!(end, num.len());
                    prop_assert_eq!(Some(v.to_bits()), parse_f64(num.as_bytes()).map(f64::to_bits), "{}", num);
                }
                // Only mantissas past 15 digits may leave the fast paths.
                None => prop_assert!(num.bytes().filter(u8::is_ascii_digit).count() > 15, "{}", num),
            }
        }

        /// Whole arrays, the way meshes are written, read the same as number by number.
        #[test]
        fn arrays_read_like_their_numbers(vals in prop::collection::vec((0u32..20_000_000, -5000i32..5000, 0u32..10_000_000), 1..200)) {
            let ints: Vec<u32> = vals.iter().map(|v| v.0).collect();
            let floats: Vec<String> = vals.iter().map(|v| format!("{}.{}", v.1, v.2)).collect();
            let mut text = String::from("[ ");
            for (i, v) in ints.iter().enumerate() {
                text.push_str(&v.to_string());
                text.push_str(if i % 4 == 3 { "\n    " } else { " " });
            }
            text.push_str("] [\n");
            for f in &floats {
                text.push_str(f);
                text.push_str("  ");
            }
            text.push(']');
            let mut lx = Lexer::new(text.as_bytes(), FileId(0));
            lx.next_token().unwrap();
            let mut got = Vec::new();
            lx.read_u32_array(&mut got).unwrap();
            prop_assert_eq!(&got, &ints);
            lx.next_token().unwrap();
            let mut fl = Vec::new();
            lx.read_f32_array(&mut fl).unwrap();
            let want: Vec<u32> = floats.iter().map(|f| fast_float_f32(f).unwrap().to_bits()).collect();
            let fl: Vec<u32> = fl.iter().map(|f| f.to_bits()).collect();
            prop_assert_eq!(fl, want);
            prop_assert_eq!(lx.loc().line, 1 + text.matches('\n').count() as u32);
        }
    }
}
