use super::*;

const ASCII_QUAD: &str = "ply\nformat ascii 1.0\ncomment x\nelement vertex 4\nproperty float x\nproperty float y\n\
    property float z\nproperty float s\nproperty float t\nelement face 1\nproperty list uchar int vertex_indices\n\
    end_header\n0 0 0 0 0\n1 0 0 1 0\n1 1 0 1 1\n0 1 0 0 1\n4 0 1 2 3\n";

#[test]
fn ascii_quad_with_st() {
    let m = parse_ply(ASCII_QUAD.as_bytes()).unwrap();
    assert_eq!(m.positions.len(), 4);
    assert_eq!(m.indices, [0, 1, 2, 0, 2, 3]);
    assert_eq!(m.uvs.unwrap()[2], [1.0, 1.0]);
    assert!(m.normals.is_none());
}

#[test]
fn binary_le_roundtrip() {
    let mesh = Mesh {
        positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        normals: Some(vec![[0.0, 0.0, 1.0]; 3]),
        uvs: Some(vec![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]),
        indices: vec![0, 1, 2],
        face_ids: None,
    };
    assert_eq!(parse_ply(&write_ply_binary_le(&mesh)).unwrap(), mesh);
}

#[test]
fn binary_be_with_extra_props_and_elements() {
    let mut b = b"ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty double x\nproperty double y\n\
        property double z\nproperty uchar red\nelement face 1\nproperty list uint short vertex_indices\n\
        property list uchar int face_indices\nelement edge 1\nproperty int a\nend_header\n"
        .to_vec();
    for p in [[0.0f64, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0]] {
        p.iter().for_each(|c| b.extend_from_slice(&c.to_be_bytes()));
        b.push(255);
    }
    b.extend_from_slice(&3u32.to_be_bytes());
    for i in [2i16, 1, 0] {
        b.extend_from_slice(&i.to_be_bytes());
    }
    b.push(1);
    b.extend_from_slice(&7i32.to_be_bytes());
    b.extend_from_slice(&9i32.to_be_bytes());
    let m = parse_ply(&b).unwrap();
    assert_eq!(m.positions[1], [2.0, 0.0, 0.0]);
    assert_eq!(m.indices, [2, 1, 0]);
}

#[test]
fn errors_name_element_and_property() {
    let bad = ASCII_QUAD.replace("4 0 1 2 3", "4 0 1 2 9");
    let e = parse_ply(bad.as_bytes()).unwrap_err().to_string();
    assert!(
        e.contains("`face` property `vertex_indices`") && e.contains("out of range"),
        "{e}"
    );
    let trunc = &ASCII_QUAD.as_bytes()[..ASCII_QUAD.len() - 8];
    assert!(parse_ply(trunc)
        .unwrap_err()
        .to_string()
        .contains("vertex_indices"));
    assert!(
        parse_ply(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty foo x\nend_header\n")
            .is_err()
    );
    assert!(parse_ply(b"plx\n").is_err());
    assert!(parse_ply(b"ply\nformat ascii 1.0\nelement vertex 99999999999\nproperty float x\nproperty float y\nproperty float z\nend_header\n").is_err());
    assert!(parse_ply(
        b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\nend_header\n"
    )
    .is_err());
}

const TRI_HEAD: &str = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n";

#[test]
fn regression_ply_ascii_missing_value_names_the_line() {
    let ply = format!("{TRI_HEAD}element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0\n1 1 0\n0 1 0\n3 0 1 2\n");
    let e = parse_ply(ply.as_bytes()).unwrap_err().to_string();
    assert!(e.contains("line 11") && e.contains("missing"), "{e}");
    let extra = format!("{TRI_HEAD}element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0 7\n1 1 0\n0 1 0\n3 0 1 2\n");
    let e = parse_ply(extra.as_bytes()).unwrap_err().to_string();
    assert!(e.contains("line 11") && e.contains("more values"), "{e}");
    // Blank lines between items are fine.
    let blank = format!("{TRI_HEAD}element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n");
    assert_eq!(parse_ply(blank.as_bytes()).unwrap().indices, vec![0, 1, 2]);
}

#[test]
fn regression_ply_tristrips_become_triangles() {
    // Two strips separated by -1; the second joins back with a repeated index (skipped).
    let ply = format!("{TRI_HEAD}element tristrips 1\nproperty list int int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n9 0 1 2 3 -1 3 3 2 1\n");
    let m = parse_ply(ply.as_bytes()).unwrap();
    assert_eq!(m.indices, vec![0, 1, 2, 2, 1, 3, 2, 3, 1]);
    // Binary little-endian too.
    let mut bin = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement tristrips 1\nproperty list int int vertex_indices\nend_header\n".to_vec();
    for v in [0f32, 0., 0., 1., 0., 0., 0., 1., 0.] {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    for i in [3i32, 0, 1, 2] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    assert_eq!(parse_ply(&bin).unwrap().indices, vec![0, 1, 2]);
    let bad = format!("{TRI_HEAD}element tristrips 1\nproperty list int int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 7\n");
    assert!(parse_ply(bad.as_bytes())
        .unwrap_err()
        .to_string()
        .contains("out of range"));
}

#[test]
fn regression_ply_degenerate_faces_are_counted() {
    let ply = format!("{TRI_HEAD}element face 3\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n0\n2 0 1\n");
    let (m, r) = parse_ply_report(ply.as_bytes()).unwrap();
    assert_eq!(m.indices, vec![0, 1, 2]);
    assert_eq!(r.dropped_faces, 2);
    assert_eq!(r.first_dropped, Some((1, Some(15))));
    assert!(r.warning().unwrap().contains("2 face(s)"));
    // The binary fast path counts them too.
    let mut bin = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n".to_vec();
    for v in [0f32, 0., 0., 1., 0., 0., 0., 1., 0.] {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    bin.push(3);
    for i in [0i32, 1, 2] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    bin.push(2);
    for i in [0i32, 1] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    let (m, r) = parse_ply_report(&bin).unwrap();
    assert_eq!(
        (m.indices.len(), r.dropped_faces, r.first_dropped),
        (3, 1, Some((1, None)))
    );
}

/// Binary `uchar`/`int` and `uchar`/`uint` face lists take a fast path; it must agree
/// with the generic reader (ASCII) on quads, bounds and negative indices.
#[test]
fn binary_face_fast_path_matches_generic_reader() {
    let header = |format: &str, item: &str| {
        format!(
            "ply\nformat {format} 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
             property float z\nelement face 2\nproperty list uchar {item} vertex_indices\nend_header\n"
        )
    };
    let faces: [&[i32]; 2] = [&[0, 1, 2, 3], &[3, 2, 1]];
    let positions = [
        [0.0f32, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
    ];
    let binary = |le: bool, item: &str, faces: &[&[i32]]| {
        let format = if le {
            "binary_little_endian"
        } else {
            "binary_big_endian"
        };
        let mut b = header(format, item).into_bytes();
        for p in positions.iter().flatten() {
            b.extend_from_slice(&if le { p.to_le_bytes() } else { p.to_be_bytes() });
        }
        for f in faces {
            b.push(f.len() as u8);
            for i in *f {
                b.extend_from_slice(&if le { i.to_le_bytes() } else { i.to_be_bytes() });
            }
        }
        b
    };
    let mut ascii = header("ascii", "int");
    for p in positions {
        ascii += &format!("{} {} {}\n", p[0], p[1], p[2]);
    }
    for f in faces {
        let list: Vec<String> = f.iter().map(i32::to_string).collect();
        ascii += &format!("{} {}\n", f.len(), list.join(" "));
    }
    let generic = parse_ply(ascii.as_bytes()).unwrap();
    assert_eq!(generic.indices, [0, 1, 2, 0, 2, 3, 3, 2, 1]);
    for le in [true, false] {
        for item in ["int", "uint"] {
            assert_eq!(parse_ply(&binary(le, item, &faces)).unwrap(), generic);
            for bad in [-1, 4] {
                let e = parse_ply(&binary(le, item, &[&[0, 1, bad], &[0, 1, 2]]))
                    .unwrap_err()
                    .to_string();
                assert!(
                    e.contains("out of range") && e.contains("vertex_indices"),
                    "{e}"
                );
            }
            let whole = binary(le, item, &faces);
            let e = parse_ply(&whole[..whole.len() - 2])
                .unwrap_err()
                .to_string();
            assert!(e.contains("truncated"), "{e}");
        }
    }
}

/// Fuzz finding (ply target, timeout): `element ve2rtex 433333333333333334` with no
/// properties looped 4e17 times doing nothing; and a property-carrying element whose
/// count exceeds the bytes left now fails at once instead of item by item.
#[test]
fn regression_ply_huge_element_count_timeout() {
    let no_props = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
          property float z\nelement ve2rtex 433333333333333334\nend_header\n0 0 0\n";
    let started = std::time::Instant::now();
    assert_eq!(parse_ply(no_props).unwrap().positions.len(), 1);
    // Second finding: the same with an element the reader knows by name (`tristrips`,
    // `face`): their branches looped over the count before the no-property guard.
    for name in ["tristrips", "face"] {
        let named = format!(
            "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n\
             property float y\nproperty float z\nelement {name} 7777777777777777778\n\
             end_header\n"
        );
        let mut bytes = named.into_bytes();
        bytes.extend_from_slice(&[0u8; 12]);
        let mesh = parse_ply(&bytes).unwrap();
        assert_eq!((mesh.positions.len(), mesh.indices.len()), (1, 0), "{name}");
    }
    let face = b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n\
          property float y\nproperty float z\nelement face 4000000000\n\
          property list uchar int vertex_indices\nend_header\n\0\0\0\0\0\0\0\0\0\0\0\0";
    let e = parse_ply(face).unwrap_err().to_string();
    assert!(e.contains("4000000000 items declared"), "{e}");
    assert!(started.elapsed() < std::time::Duration::from_secs(1));
}

#[test]
fn gz_file() {
    use std::io::Write;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.ply.gz");
    let mut enc = flate2::write::GzEncoder::new(
        std::fs::File::create(&path).unwrap(),
        flate2::Compression::fast(),
    );
    enc.write_all(ASCII_QUAD.as_bytes()).unwrap();
    enc.finish().unwrap();
    assert_eq!(read_ply(&path).unwrap().triangle_count(), 2);
}

#[test]
fn regression_ply_body_with_more_faces_than_declared_is_an_error() {
    // ASCII: a second face line where the header declares one.
    let ply = format!("{TRI_HEAD}element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n");
    let e = parse_ply(ply.as_bytes()).unwrap_err().to_string();
    assert!(
        e.contains("line 15")
            && e.contains("more than the header declares")
            && e.contains("`face`"),
        "{e}"
    );
    // Trailing blank lines are not data.
    let ok = format!("{TRI_HEAD}element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n\n\n");
    assert_eq!(parse_ply(ok.as_bytes()).unwrap().indices, vec![0, 1, 2]);
    // Binary: a second face record after the one declared, by its byte offset.
    let head = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
    let mut bin = head.to_vec();
    for v in [0f32, 0., 0., 1., 0., 0., 0., 1., 0.] {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    let face = |bin: &mut Vec<u8>| {
        bin.push(3);
        for i in [0i32, 1, 2] {
            bin.extend_from_slice(&i.to_le_bytes());
        }
    };
    face(&mut bin);
    assert_eq!(parse_ply(&bin).unwrap().indices, vec![0, 1, 2]);
    let end = bin.len();
    face(&mut bin);
    let e = parse_ply(&bin).unwrap_err().to_string();
    assert!(
        e.contains(&format!("byte {end}")) && e.contains("13 byte(s)"),
        "{e}"
    );
}

#[test]
fn face_indices_become_per_triangle_face_ids() {
    let ply = format!(
        "{TRI_HEAD}element face 2\nproperty list uchar int vertex_indices\nproperty int face_indices\nend_header\n\
         0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3 5\n3 0 2 3 9\n"
    );
    let m = parse_ply(ply.as_bytes()).unwrap();
    assert_eq!(m.indices, [0, 1, 2, 0, 2, 3, 0, 2, 3]);
    let half = crate::events::FACE_SECOND_HALF;
    assert_eq!(m.face_ids.as_deref(), Some(&[5, 5 | half, 9][..]));
    let bad = ply.replace("3 0 2 3 9", "3 0 2 3 -1");
    assert!(parse_ply(bad.as_bytes())
        .unwrap_err()
        .to_string()
        .contains("face index"));
}

/// Errors keep their cause (issue 46): an unreadable PLY file's I/O error is the source.
#[test]
fn an_unreadable_ply_keeps_its_io_error() {
    let dir = tempfile::tempdir().unwrap();
    let e = read_ply(&dir.path().join("gone.ply")).unwrap_err();
    assert!(matches!(e, PlyError::Read(_)), "{e}");
    let cause = std::error::Error::source(&e).expect("the I/O error is the source");
    assert!(cause.downcast_ref::<std::io::Error>().is_some(), "{cause}");
    assert!(e.to_string().starts_with("PLY: cannot read: "), "{e}");
}

/// Runs of binary triangles are read straight into the index buffer (`triangle_run`); where
/// a run stops (a quad, a degenerate face, an index out of range or negative, a truncated
/// face) the generic reader takes over and must give the ASCII reader's mesh, report and
/// errors, naming the face where the run stopped.
#[test]
fn binary_triangle_runs_match_the_generic_reader() {
    let vertices = 5usize;
    let file = |format: &str, item: &str, faces: &[Vec<i32>]| {
        let mut b = format!(
            "ply\nformat {format} 1.0\nelement vertex {vertices}\nproperty float x\nproperty float y\n\
             property float z\nelement face {}\nproperty list uchar {item} vertex_indices\nend_header\n",
            faces.len()
        )
        .into_bytes();
        let le = format == "binary_little_endian";
        for v in 0..vertices {
            let p = [v as f32, (v * v) as f32, 0.5];
            for c in p {
                if format == "ascii" {
                    b.extend_from_slice(format!("{c} ").as_bytes());
                } else {
                    b.extend_from_slice(&if le { c.to_le_bytes() } else { c.to_be_bytes() });
                }
            }
            if format == "ascii" {
                b.push(b'\n');
            }
        }
        for f in faces {
            if format == "ascii" {
                let list: Vec<String> = f.iter().map(i32::to_string).collect();
                b.extend_from_slice(format!("{} {}\n", f.len(), list.join(" ")).as_bytes());
                continue;
            }
            b.push(f.len() as u8);
            for i in f {
                b.extend_from_slice(&if le { i.to_le_bytes() } else { i.to_be_bytes() });
            }
        }
        b
    };
    let mut faces: Vec<Vec<i32>> = (0..40)
        .map(|i| vec![i % 5, (i + 1) % 5, (i + 3) % 5])
        .collect();
    faces.insert(7, vec![0, 1, 2, 3, 4]);
    faces.insert(20, vec![1, 2]);
    let want = parse_ply_report(&file("ascii", "int", &faces)).unwrap();
    assert_eq!(want.0.indices.len(), (40 + 3) * 3);
    assert_eq!(want.1.dropped_faces, 1);
    for format in ["binary_little_endian", "binary_big_endian"] {
        for item in ["int", "uint"] {
            let (mesh, report) = parse_ply_report(&file(format, item, &faces)).unwrap();
            assert_eq!(mesh, want.0);
            // Binary faces have no line to name.
            assert_eq!(report.dropped_faces, want.1.dropped_faces);
            assert_eq!(report.first_dropped, Some((20, None)));
            for bad in [-1, 5, i32::MAX] {
                let mut faces = faces.clone();
                faces[30][1] = bad;
                let e = parse_ply(&file(format, item, &faces))
                    .unwrap_err()
                    .to_string();
                let a = parse_ply(&file("ascii", "int", &faces))
                    .unwrap_err()
                    .to_string();
                assert!(e.contains("out of range") && e.contains("30"), "{e}");
                // The same words as the generic reader's, less ASCII's line number (a `uint`
                // -1 is 4294967295 in binary).
                if item == "int" {
                    assert_eq!(e.rsplit(':').next(), a.rsplit(':').next(), "{e} / {a}");
                }
            }
            let whole = file(format, item, &faces);
            let e = parse_ply(&whole[..whole.len() - 2])
                .unwrap_err()
                .to_string();
            assert!(e.contains("truncated") && e.contains("41"), "{e}");
        }
    }
}
