use super::*;

fn meshes(text: &str) -> Result<Vec<ObjMesh>, ObjError> {
    let mut out = Vec::new();
    read::<ObjError>(text.as_bytes(), |m| {
        out.push(m);
        Ok(())
    })?;
    Ok(out)
}

#[test]
fn groups_quads_and_face_ids() {
    let m = meshes(
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nvn 0 0 1\nvn 0 0 1\nvn 0 0 1\n\
             g quad\nusemtl sand\nf 1//1 2//2 3//3 4//4\nf 1//1 3//3 4//4\n\
             g tri\nv 5 5 5\nf -1 -2 -3\n",
    )
    .unwrap();
    assert_eq!(m.len(), 2);
    assert_eq!(m[0].material, "sand");
    assert_eq!((m[0].group.as_str(), m[1].group.as_str()), ("quad", "tri"));
    assert_eq!(m[0].mesh.indices, [0, 1, 2, 0, 2, 3, 0, 2, 3]);
    // Ptex faces: the quad's two halves, then the triangle as face 1.
    let half = crate::events::FACE_SECOND_HALF;
    assert_eq!(m[0].mesh.face_ids.as_deref(), Some(&[0, half, 1][..]));
    assert_eq!(m[0].mesh.normals.as_ref().unwrap().len(), 4);
    assert_eq!(m[0].line, 11);
    // Negative indices: the last three vertices, in the file's order.
    assert_eq!(m[1].mesh.positions[2], [5.0, 5.0, 5.0]);
    assert_eq!(m[1].mesh.indices, [2, 1, 0]);
    assert_eq!(m[1].material, "sand");
}

#[test]
fn scattered_corners_are_renumbered() {
    let m = meshes("v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nvn 1 0 0\nf 1//2 2//1 3//1\n").unwrap();
    assert_eq!(m[0].mesh.positions.len(), 3);
    assert_eq!(m[0].mesh.normals.as_ref().unwrap()[0], [1.0, 0.0, 0.0]);
}

#[test]
fn errors_name_the_line() {
    for (text, line, needle) in [
        ("v 0 0\n", 1, "3 numbers"),
        ("v 0 0 0\nv 0 0 x\n", 2, "not a number"),
        ("v 0 0 0\nf 1 2 3\n", 2, "out of range"),
        ("v 0 0 0\nv 0 0 0\nf 1 2\n", 3, "at least 3"),
        ("v nan 0 0\n", 1, "finite"),
        ("v 0 0 0\nv 0 0 0\nv 0 0 0\nf 1 2 x\n", 4, "not an index"),
        ("v 0 0 0\nv 0 0 0\nv 0 0 0\nf 1 2 -\n", 4, "not an index"),
    ] {
        let e = meshes(text).unwrap_err();
        assert_eq!(e.line, line, "{text}");
        assert!(e.message.contains(needle), "{text}: {}", e.message);
    }
}
