use super::*;
use crate::FileId;

fn parse(src: &str) -> Result<ParamList<'_>, String> {
    let mut lx = Lexer::new(src.as_bytes(), FileId(0));
    ParamList::parse(&mut lx).map_err(|e| match e {
        ParamError::Lex(e) => format!("lex {:?} {}", e.kind, e.loc.column),
        ParamError::Bad(t, m) => format!("{}:{} {m}", t.loc.column, t.display()),
    })
}

#[test]
fn all_value_forms() {
    let p = parse(
        r#""float fov" 30 "integer n" [1 2] "string s" "x" "bool b" true "bool c" "false"
               "rgb Kd" [.5 .5 .5] "point2 uv" [0 1 1 0] "texture t" ["tx"] "spectrum k" "a.spd"
               "spectrum e" [400 1 500 2] "blackbody L" 6500 Shape"#,
    )
    .unwrap();
    assert_eq!(p.float("fov"), Some(30.0));
    assert_eq!(p.int("n"), Some(1));
    assert_eq!(p.string("s"), Some("x"));
    assert_eq!(p.bool("b"), Some(true));
    assert_eq!(p.bool("c"), Some(false));
    assert_eq!(p.nums("Kd"), Some(&[0.5f32, 0.5, 0.5][..]));
    assert_eq!(p.nums("uv").map(|v| v.len()), Some(4));
    assert_eq!(p.texture("t"), Some("tx"));
    assert_eq!(
        p.get("k").map(|p| &p.values),
        Some(&Values::Strs(vec!["a.spd".into()]))
    );
    assert_eq!(p.nums("e").map(|v| v.len()), Some(4));
    assert_eq!(p.nums("L"), Some(&[6500.0f32][..]));
    assert_eq!(p.params.len(), 11);
}

#[test]
fn v3_aliases() {
    let p = parse(r#""color Kd" [1 0 0] "point P" [0 0 0] "normal N" [0 0 1] "vector v" [1 1 1]"#)
        .unwrap();
    let tys: Vec<_> = p.params.iter().map(|p| p.ty).collect();
    assert_eq!(
        tys,
        [
            ParamType::Rgb,
            ParamType::Point3,
            ParamType::Normal3,
            ParamType::Vector3
        ]
    );
}

#[test]
fn errors_name_the_token() {
    assert_eq!(
        parse(r#""float fov" "abc""#).unwrap_err(),
        "13:\"abc\" expected a number for `float`"
    );
    assert_eq!(
        parse(r#""flot fov" 1"#).unwrap_err(),
        "1:\"flot fov\" unknown parameter type `flot`"
    );
    assert_eq!(
        parse(r#""float" 1"#).unwrap_err(),
        "1:\"float\" expected \"type name\""
    );
    assert!(parse(r#""rgb Kd" [1 2]"#)
        .unwrap_err()
        .contains("not a multiple of 3"));
    assert!(parse(r#""string s" [ 1 ]"#)
        .unwrap_err()
        .contains("expected a quoted string"));
    assert!(parse(r#""bool b" maybe"#)
        .unwrap_err()
        .contains("true or false"));
    assert!(parse(r#""integer i" 1.5"#).unwrap_err().contains("integer"));
    assert!(parse(r#""float f" [ 1 2"#)
        .unwrap_err()
        .starts_with("lex UnterminatedArray"));
}
