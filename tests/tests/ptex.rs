//! Issue 47 item 6: Ptex. Tests write their own `.ptx` files (motu-texture's writer): a grid
//! of quads, each face a colour of its own, imported from pbrt-v3 and pbrt-v4, partitioned
//! into clusters; every backend shows each face's colour where the AOV says its triangles are;
//! streaming equals the full build; `motu report` and `motu info` count the Ptex bytes; a
//! missing and a corrupt `.ptx` are warnings naming the file, with the material's colour.

use motu_tests::{gpu_available, has_ray_query, motu, motu_json, motu_ok, render, s};
use motu_texture::ptex::{write, DataType, Encoding, WriteFace};
use std::path::Path;

/// Quads a side of the grid (N × N faces, 2 N² triangles).
const N: usize = 8;

/// Face f's colour: one of six saturated hues, neighbours differing.
fn face_rgb(f: usize) -> [u8; 3] {
    const HUES: [[u8; 3]; 6] = [
        [220, 20, 20],
        [20, 220, 20],
        [20, 20, 220],
        [220, 220, 20],
        [20, 220, 220],
        [220, 20, 220],
    ];
    let (x, y) = (f % N, f / N);
    HUES[(x + 2 * y) % 6]
}

/// Which channels are "on" in a colour (above half its brightest).
fn pattern(c: [f32; 3]) -> [bool; 3] {
    let m = c[0].max(c[1]).max(c[2]);
    c.map(|v| v > 0.5 * m)
}

/// The Ptex file: N² faces of 4×4 texels (u8 RGB), every encoding the reader knows.
fn write_ptex(path: &Path) {
    let faces: Vec<WriteFace> = (0..N * N)
        .map(|f| {
            let rgb = face_rgb(f);
            let encoding = match f % 4 {
                0 => Encoding::Constant,
                1 => Encoding::Zipped,
                2 => Encoding::DiffZipped,
                _ => Encoding::Tiled(1, 1),
            };
            WriteFace {
                ulog2: 2,
                vlog2: 2,
                data: rgb.repeat(16),
                encoding,
            }
        })
        .collect();
    write(path, DataType::U8, 3, None, 1, &faces).unwrap();
}

/// The grid in the y = 0 plane, [-4, 4]², quad (x, z) = face x + N z; its triangles
/// (v0 v1 v2), (v0 v2 v3) carry the face in pbrt's `faceIndices`.
fn grid_shape() -> String {
    let mut p = String::new();
    let mut idx = String::new();
    let mut faces = String::new();
    let step = 8.0 / N as f32;
    for z in 0..N {
        for x in 0..N {
            let (x0, z0) = (-4.0 + x as f32 * step, -4.0 + z as f32 * step);
            let b = 4 * (x + N * z);
            p += &format!(
                "{x0} 0 {z0}  {} 0 {z0}  {} 0 {}  {x0} 0 {}  ",
                x0 + step,
                x0 + step,
                z0 + step,
                z0 + step
            );
            idx += &format!("{b} {} {}  {b} {} {}  ", b + 1, b + 2, b + 2, b + 3);
            let f = x + N * z;
            faces += &format!("{f} {f} ");
        }
    }
    format!(
        "Shape \"trianglemesh\" \"point P\" [{p}] \"integer indices\" [{idx}] \"integer faceIndices\" [{faces}]"
    )
}

/// Side triangles (outside the grid, x > 4.5) with a missing and a corrupt Ptex file.
fn broken_shapes() -> &'static str {
    r#"AttributeBegin
  Material "matte" "texture Kd" "gone"
  Shape "trianglemesh" "point P" [4.5 0 -3  6 0 -3  6 0 -1] "integer indices" [0 1 2]
AttributeEnd
AttributeBegin
  Material "matte" "texture Kd" "bad"
  Shape "trianglemesh" "point P" [4.5 0 1  6 0 1  6 0 3] "integer indices" [0 1 2]
AttributeEnd
"#
}

fn write_scene(dir: &Path, v4: bool) -> std::path::PathBuf {
    write_ptex(&dir.join("grid.ptx"));
    std::fs::write(
        dir.join("bad.ptx"),
        b"Ptex\x01\0\0\0 this is not a ptex file",
    )
    .unwrap();
    let (film, colour, material) = if v4 {
        ("rgb", "spectrum", "\"diffuse\" \"texture reflectance\"")
    } else {
        ("image", "color", "\"matte\" \"texture Kd\"")
    };
    let text = format!(
        r#"LookAt 0 13 0  0 0 0  0 0 1
Camera "perspective" "float fov" [50]
Film "{film}" "integer xresolution" [64] "integer yresolution" [64]
WorldBegin
LightSource "distant" "point from" [0 10 0] "point to" [0 0 0] "rgb L" [2.5 2.5 2.5]
Texture "grid" "{colour}" "ptex" "string filename" "grid.ptx"
Texture "gone" "{colour}" "ptex" "string filename" "missing.ptx"
Texture "bad" "{colour}" "ptex" "string filename" "bad.ptx"
AttributeBegin
  Material {material} "grid"
  {grid}
AttributeEnd
{broken}"#,
        grid = grid_shape(),
        broken = broken_shapes().replace("\"matte\" \"texture Kd\"", material),
    );
    let scene = dir.join(if v4 { "v4.pbrt" } else { "v3.pbrt" });
    std::fs::write(&scene, text).unwrap();
    scene
}

fn read_png(path: &Path) -> (u32, u32, Vec<u8>) {
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut r = dec.read_info().unwrap();
    let mut buf = vec![0u8; r.output_buffer_size().unwrap()];
    let info = r.next_frame(&mut buf).unwrap();
    buf.truncate(info.buffer_size());
    (info.width, info.height, buf)
}

/// Per pixel: (source mesh, primitive) of the AOV file, `None` on a miss.
fn read_aov(path: &Path) -> Vec<Option<(u32, u32)>> {
    let b = std::fs::read(path).unwrap();
    assert_eq!(&b[..8], b"MOTUAOV\0");
    b[32..]
        .chunks_exact(16)
        .map(|r| {
            let mesh = u32::from_le_bytes(r[0..4].try_into().unwrap());
            let prim = u32::from_le_bytes(r[4..8].try_into().unwrap());
            (mesh != u32::MAX).then_some((mesh, prim))
        })
        .collect()
}

/// Checks the image `png` against the AOV `aov`: every pixel on the grid (mesh 0, the one with
/// 2 N² triangles) shows its face's hue (triangle t is face t / 2); the two broken triangles
/// show the material's grey. Returns how many distinct faces were seen.
fn check_faces(png: &Path, aov: &Path) -> usize {
    let (w, h, rgba) = read_png(png);
    let hits = read_aov(aov);
    assert_eq!(hits.len(), (w * h) as usize);
    let channels = if rgba.len() == hits.len() * 4 { 4 } else { 3 };
    let mut seen = std::collections::BTreeSet::new();
    let (mut grid, mut grey) = (0, 0);
    for (i, hit) in hits.iter().enumerate() {
        let Some((mesh, prim)) = *hit else { continue };
        let c: [f32; 3] = std::array::from_fn(|k| f32::from(rgba[channels * i + k]));
        if mesh == 0 {
            assert!((prim as usize) < 2 * N * N, "primitive {prim}");
            let face = prim as usize / 2;
            let want = face_rgb(face).map(f32::from);
            assert_eq!(
                pattern(c),
                pattern(want),
                "pixel {i} (face {face}): {c:?}, want the hue of {want:?}"
            );
            seen.insert(face);
            grid += 1;
        } else {
            // A missing or corrupt Ptex file: the material's constant colour (grey).
            let spread = c[0].max(c[1]).max(c[2]) - c[0].min(c[1]).min(c[2]);
            assert!(spread <= 3.0, "pixel {i} (mesh {mesh}): {c:?} is not grey");
            grey += 1;
        }
    }
    assert!(grid > 1000, "{grid} grid pixels");
    assert!(grey > 10, "{grey} pixels on the broken triangles");
    seen.len()
}

fn import_checked(scene: &Path, pkg: &Path, extra: &[&str]) -> serde_json::Value {
    let mut args = vec!["import", s(scene), "-o", s(pkg), "--json"];
    args.extend_from_slice(extra);
    let out = motu(&args);
    assert!(out.status.success(), "{out:?}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    for file in ["missing.ptx", "bad.ptx"] {
        assert!(
            stderr.contains(file) && stderr.contains("Ptex texture not read"),
            "{file} is warned about: {stderr}"
        );
    }
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn ptex_faces_render_on_every_backend_and_stream() {
    let dir = tempfile::tempdir().unwrap();
    let scene = write_scene(dir.path(), false);
    let pkg = dir.path().join("v3.motu");
    // A bound of 16 triangles splits the grid into clusters: face ids survive partitioning.
    import_checked(
        &scene,
        &pkg,
        &["--max-blas-triangles", "16", "--ptex-max", "2"],
    );
    let info = motu_json(&["info", s(&pkg), "--json"]);
    assert!(info["partition_clusters"].as_u64().unwrap() >= 4, "{info}");
    assert_eq!(info["ptex_materials"], 3, "{info}");
    assert_eq!(
        info["ptex_textures"], 1,
        "the broken files have no faces: {info}"
    );
    assert_eq!(info["ptex_faces"], (N * N) as u64, "{info}");
    // The words: the mesh count, one mesh table entry and its per-triangle table (not the
    // quad pattern: no halves), two words a face, the texels (constant faces 1, the others
    // 2×2 at --ptex-max 2); the two broken textures one word each.
    let constant = (0..N * N).filter(|f| f % 4 == 0).count();
    let words = 1 + 2 + 2 * N * N + 2 * N * N + constant + 4 * (N * N - constant);
    assert_eq!(info["ptex_bytes"], (4 * words) as u64, "{info}");
    let report = motu_json(&["report", s(&pkg), "--json"]);
    let want = format!("\"ptex_bytes\":{}", 4 * (words + 2));
    assert!(report.to_string().contains(&want), "{want} in {report}");
    // --ptex-max bounds the texels a face keeps: at 1 every face is one texel.
    let small = dir.path().join("small.motu");
    import_checked(&scene, &small, &["--ptex-max", "1"]);
    let words1 = 1 + 2 + 2 * N * N + 2 * N * N + N * N;
    assert_eq!(
        motu_json(&["info", s(&small), "--json"])["ptex_bytes"],
        (4 * words1) as u64
    );

    let cpu = dir.path().join("cpu.aov");
    render(&pkg, "cpu", &cpu, &["--ao-samples", "0"]);
    let faces = check_faces(&cpu.with_extension("png"), &cpu);
    assert!(faces >= N * N * 3 / 4, "{faces} faces seen");

    if !gpu_available() {
        return;
    }
    let mut backends = vec!["pipeline"];
    if has_ray_query() {
        backends.push("query");
    }
    let (_, _, cpu_png) = read_png(&cpu.with_extension("png"));
    for b in backends {
        let gpu = dir.path().join(format!("{b}.aov"));
        render(&pkg, b, &gpu, &["--ao-samples", "0"]);
        check_faces(&gpu.with_extension("png"), &gpu);
        // Hits on a shared edge may name either triangle (the shading test allows as much).
        motu_ok(&["compare", s(&cpu), s(&gpu), "--max-mismatch", "0.002"]);
        let (_, _, g) = read_png(&gpu.with_extension("png"));
        let worst = g.iter().zip(&cpu_png).map(|(a, c)| a.abs_diff(*c)).max();
        assert!(
            worst <= Some(2),
            "{b}: worst channel difference {worst:?} to the CPU"
        );
        // Streaming: the Ptex texels arrive with the meshes that sample them.
        let streamed = dir.path().join(format!("{b}-stream.aov"));
        let st = render(
            &pkg,
            b,
            &streamed,
            // The streamer (64 MiB holds this scene: it would render the full build).
            &[
                "--ao-samples",
                "0",
                "--stream",
                "--stream-always",
                "--vram-budget",
                "64MiB",
            ],
        );
        assert_eq!(st["stream"]["totals"]["incomplete_frames"], 0, "{st}");
        assert!(
            st["stream"]["frames"][0]["resident_textures"].as_u64() >= Some(1),
            "{st}"
        );
        motu_ok(&["compare", s(&gpu), s(&streamed), "--max-mismatch", "0"]);
        let (_, _, sp) = read_png(&streamed.with_extension("png"));
        assert!(sp == g, "{b}: the streamed image equals the full build's");
    }
}

#[test]
fn ptex_from_pbrt_v4() {
    let dir = tempfile::tempdir().unwrap();
    let scene = write_scene(dir.path(), true);
    let pkg = dir.path().join("v4.motu");
    import_checked(&scene, &pkg, &["--pbrt-version", "4"]);
    let cpu = dir.path().join("cpu.aov");
    render(&pkg, "cpu", &cpu, &["--ao-samples", "0"]);
    let faces = check_faces(&cpu.with_extension("png"), &cpu);
    assert!(faces >= N * N * 3 / 4, "{faces} faces seen");
}

/// Moana's JSON+OBJ base package: the ground group's `<colorMap>/ground.ptx`, its quads the
/// Ptex faces in file order (a quad's two triangles its halves).
#[test]
fn ptex_from_moana_json_obj() {
    let dir = tempfile::tempdir().unwrap();
    let w = |rel: &str, text: &str| {
        let p = dir.path().join(rel);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(p, text).unwrap();
    };
    w(
        "island/json/isA/isA.json",
        r#"{"name": "isA", "matFile": "json/isA/materials.json", "geomObjFile": "obj/isA/isA.obj",
            "transformMatrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]}"#,
    );
    w(
        "island/json/isA/materials.json",
        r#"{"ground": {"baseColor": [0.5, 0.5, 0.5], "colorMap": "textures/isA/Color"}}"#,
    );
    // 2 × 2 quads over [-8, 8]², face x + 2 z.
    let mut obj = String::from("g ground\nusemtl ground\n");
    for z in 0..3 {
        for x in 0..3 {
            obj += &format!("v {} 0 {}\n", -8 + 8 * x, -8 + 8 * z);
        }
    }
    for z in 0..2 {
        for x in 0..2 {
            let v = 1 + x + 3 * z;
            obj += &format!("f {} {} {} {}\n", v, v + 1, v + 4, v + 3);
        }
    }
    w("island/obj/isA/isA.obj", &obj);
    w(
        "island/json/cameras/shotCam.json",
        r#"{"eye": [0, 20, 0], "look": [0, 0, 0], "up": [0, 0, 1], "fov": 60, "ratio": 1.0}"#,
    );
    let ptx = dir.path().join("island/textures/isA/Color/ground.ptx");
    std::fs::create_dir_all(ptx.parent().unwrap()).unwrap();
    let faces: Vec<WriteFace> = (0..4)
        .map(|f| WriteFace {
            ulog2: 1,
            vlog2: 1,
            data: face_rgb(f).repeat(4),
            encoding: Encoding::Zipped,
        })
        .collect();
    write(&ptx, DataType::U8, 3, None, 1, &faces).unwrap();
    let pkg = dir.path().join("m.motu");
    let out = motu(&["import", s(&dir.path().join("island/json")), "-o", s(&pkg)]);
    assert!(out.status.success(), "{out:?}");
    assert!(
        !String::from_utf8_lossy(&out.stderr).contains("Ptex texture not read"),
        "{out:?}"
    );
    let info = motu_json(&["info", s(&pkg), "--json"]);
    assert_eq!(info["ptex_faces"], 4, "{info}");
    let aov = dir.path().join("cpu.aov");
    render(
        &pkg,
        "cpu",
        &aov,
        &["--ao-samples", "0", "--width", "32", "--height", "32"],
    );
    let (w, h, rgba) = read_png(&aov.with_extension("png"));
    let hits = read_aov(&aov);
    let mut seen = std::collections::BTreeSet::new();
    for (i, hit) in hits.iter().enumerate() {
        let Some((_, prim)) = *hit else { continue };
        let c: [f32; 3] = std::array::from_fn(|k| f32::from(rgba[4 * i + k]));
        let face = prim as usize / 2;
        let want = face_rgb(face).map(f32::from);
        assert_eq!(pattern(c), pattern(want), "pixel {i} (face {face}): {c:?}");
        seen.insert(face);
    }
    assert_eq!(seen.len(), 4, "every face seen in a {w}×{h} image");
}
