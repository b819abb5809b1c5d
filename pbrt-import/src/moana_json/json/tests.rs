use super::*;

fn tree(s: &str) -> JResult<Node> {
    let mut r = Reader::new(s.as_bytes());
    let n = r.node()?;
    r.finish()?;
    Ok(n)
}

#[test]
fn reads_values_in_order() {
    let n = tree(r#" {"b": [1, -2.5e1, true, null], "a": "x\"y\u00e9", "c": {}} "#).unwrap();
    let keys: Vec<_> = n.members().iter().map(|(k, _)| k.as_str()).collect();
    assert_eq!(keys, ["b", "a", "c"]);
    assert_eq!(n.get("b").unwrap().items()[1].as_f64(), Some(-25.0));
    assert_eq!(n.get("a").unwrap().as_str(), Some("x\"yé"));
    assert_eq!(n.get("b").unwrap().at, 7);
}

#[test]
fn python_nan_is_a_number() {
    let n = tree("[NaN, Infinity, -Infinity]").unwrap();
    assert!(n.items()[0].as_f64().unwrap().is_nan());
    assert_eq!(n.items()[2].as_f64(), Some(f64::NEG_INFINITY));
}

#[test]
fn errors_name_the_offset() {
    for (text, offset, needle) in [
        (r#"{"a": [1, 2"#, 11, "truncated"),
        (r#"{"a" 1}"#, 5, "`:`"),
        (r#"{"a": 1,}"#, 8, "key"),
        (r#"[1 2]"#, 3, "`,` or `]`"),
        (r#"[01.]"#, 4, "digit"),
        (r#"{"a": tru"#, 9, "truncated"),
        (r#"[1] x"#, 4, "after"),
    ] {
        let e = tree(text).unwrap_err();
        assert_eq!(e.offset, offset, "{text}: {e:?}");
        assert!(e.message.contains(needle), "{text}: {e:?}");
    }
}

#[test]
fn deep_nesting_is_an_error_not_a_stack_overflow() {
    let deep = "[".repeat(100_000);
    assert!(tree(&deep).unwrap_err().message.contains("deep"));
}

#[test]
fn streams_a_map_of_matrices() {
    let text = r#"{"a.obj": {"i0": [1,0,0,0, 0,1,0,0, 0,0,1,0, 5,6,7,1]}, "b.obj": {}}"#;
    let mut r = Reader::new(text.as_bytes());
    let mut seen = Vec::new();
    r.object::<JsonError>("archive", |r, obj, _| {
        let obj = obj.into_owned();
        r.object("instances", |r, _, _| {
            let m = r.numbers::<16>("a matrix")?;
            seen.push((obj.clone(), m[12]));
            Ok(())
        })
    })
    .unwrap();
    assert_eq!(seen, [("a.obj".to_string(), 5.0)]);
    let e = Reader::new(br#"{"a": [1, 2]}"#)
        .object::<JsonError>("x", |r, _, _| r.numbers::<16>("a matrix").map(|_| ()))
        .unwrap_err();
    assert!(e.message.contains("2 numbers, not 16"), "{e:?}");
}
