//! Issue 16: scenes look like themselves. A small pbrt-v3 scene written here with real image
//! files (a PFM colour checker, a TGA alpha cut-out, a missing PNG): import warns about the
//! missing file, the shaded CPU render shows the texture and the cut-out, the budget report
//! counts the texture bytes, and every GPU backend equals the CPU oracle per pixel on the hit
//! records, alpha-tested triangles included.

use motu_tests::{gpu_available, has_ray_query, motu, motu_json, motu_ok, render, s};
use std::path::Path;

/// 8×8 RGB checker of 2×2-texel cells, red and blue (PFM: little endian, rows bottom-up).
fn write_checker_pfm(path: &Path) {
    let mut bytes = b"PF\n8 8\n-1.0\n".to_vec();
    for y in 0..8 {
        for x in 0..8 {
            let c = if (x / 2 + y / 2) % 2 == 0 {
                [0.9f32, 0.05, 0.05]
            } else {
                [0.05, 0.05, 0.9]
            };
            for v in c {
                bytes.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    std::fs::write(path, bytes).unwrap();
}

/// 8×8 uncompressed 32-bit TGA: the left half opaque, the right half fully transparent.
fn write_half_alpha_tga(path: &Path) {
    let mut bytes = vec![0u8; 18];
    bytes[2] = 2; // uncompressed true colour
    bytes[12] = 8; // width
    bytes[14] = 8; // height
    bytes[16] = 32; // bits per pixel
    bytes[17] = 8 | 0x20; // 8 alpha bits, top-left origin
    for _y in 0..8 {
        for x in 0..8 {
            let a = if x < 4 { 255 } else { 0 };
            bytes.extend_from_slice(&[255, 255, 255, a]); // BGRA
        }
    }
    std::fs::write(path, bytes).unwrap();
}

/// The scene: a checker-textured ground (y = 0), a green leaf quad above it (y = 1) whose
/// right half is cut out by its alpha texture, a quad whose texture file is missing, a
/// distant light from above. The camera looks straight down.
fn write_scene(dir: &Path) -> std::path::PathBuf {
    write_checker_pfm(&dir.join("checker.pfm"));
    write_half_alpha_tga(&dir.join("leaf.tga"));
    let scene = dir.join("scene.pbrt");
    std::fs::write(
        &scene,
        r#"LookAt 0 8 0  0 0 0  0 0 1
Camera "perspective" "float fov" [45]
Film "image" "integer xresolution" [64] "integer yresolution" [64]
WorldBegin
LightSource "distant" "point from" [0.3 10 0.2] "point to" [0 0 0] "rgb L" [2.5 2.5 2.5]
Texture "checks" "spectrum" "imagemap" "string filename" "checker.pfm"
Texture "leafalpha" "float" "imagemap" "string filename" "leaf.tga"
Texture "gone" "spectrum" "imagemap" "string filename" "missing.png"
AttributeBegin
  Material "matte" "texture Kd" "checks"
  Shape "trianglemesh" "point P" [-3 0 -3  3 0 -3  3 0 3  -3 0 3]
    "float uv" [0 0  1 0  1 1  0 1] "integer indices" [0 1 2  0 2 3]
AttributeEnd
AttributeBegin
  Material "matte" "rgb Kd" [0.1 0.7 0.1]
  Shape "trianglemesh" "point P" [-2 1 -2  2 1 -2  2 1 2  -2 1 2]
    "float uv" [0 0  1 0  1 1  0 1] "integer indices" [0 1 2  0 2 3]
    "texture alpha" "leafalpha"
AttributeEnd
AttributeBegin
  Material "matte" "texture Kd" "gone"
  Shape "trianglemesh" "point P" [2.2 0.5 2.2  2.8 0.5 2.2  2.8 0.5 2.8]
    "integer indices" [0 1 2]
AttributeEnd
"#,
    )
    .unwrap();
    scene
}

fn read_png(path: &Path) -> (u32, u32, Vec<u8>) {
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut r = dec.read_info().unwrap();
    let mut buf = vec![0u8; r.output_buffer_size().unwrap()];
    let info = r.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgba);
    buf.truncate(info.buffer_size());
    (info.width, info.height, buf)
}

#[test]
fn textures_alpha_cutouts_and_a_missing_texture() {
    let dir = tempfile::tempdir().unwrap();
    let scene = write_scene(dir.path());
    let pkg = dir.path().join("scene.motu");
    let out = motu(&["import", s(&scene), "-o", s(&pkg), "--json"]);
    assert!(out.status.success(), "{out:?}");
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(summary["warnings"].as_u64().unwrap() >= 1, "{summary}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("missing.png") && stderr.contains("texture file missing"),
        "the missing texture is warned about: {stderr}"
    );
    let info = motu_json(&["info", s(&pkg), "--json"]);
    assert!(info["warnings"].as_u64().unwrap() >= 1, "{info}");

    // The budget report counts the two textures' mip chains (8×8 → 1×1: 85 texels each) and
    // their records.
    let report = motu_json(&["report", s(&pkg), "--json"]);
    let want = 2 * (85 * 4 + 16);
    let found = report
        .to_string()
        .contains(&format!("\"texture_bytes\":{want}"));
    assert!(found, "texture_bytes {want} not in the report: {report}");

    // CPU render: the leaf's opaque half is green, its cut-out half shows the red/blue ground.
    let aov = dir.path().join("cpu.aov");
    render(&pkg, "cpu", &aov, &["--ao-samples", "0"]);
    let (w, h, rgba) = read_png(&aov.with_extension("png"));
    let px = |x: u32, y: u32| {
        let i = 4 * (y * w + x) as usize;
        [rgba[i] as i32, rgba[i + 1] as i32, rgba[i + 2] as i32]
    };
    let green = |c: [i32; 3]| c[1] > c[0] + 30 && c[1] > c[2] + 30;
    let red_or_blue = |c: [i32; 3]| (c[0] > c[1] + 40) || (c[2] > c[1] + 40);
    // Sample a band across the image centre, left and right of the middle.
    let (mut greens, mut grounds) = ([0, 0], [0, 0]);
    for y in h / 2 - 4..h / 2 + 4 {
        for (side, xs) in [(0usize, w / 2 - 10..w / 2 - 2), (1, w / 2 + 2..w / 2 + 10)] {
            for x in xs {
                let c = px(x, y);
                greens[side] += usize::from(green(c));
                grounds[side] += usize::from(red_or_blue(c));
            }
        }
    }
    let (leaf_side, cut_side) = if greens[0] > greens[1] {
        (0, 1)
    } else {
        (1, 0)
    };
    assert!(greens[leaf_side] >= 60, "leaf half green: {greens:?}");
    assert_eq!(
        greens[cut_side], 0,
        "cut-out half shows no leaf: {greens:?}"
    );
    assert!(
        grounds[cut_side] >= 60,
        "the textured ground shows through: {grounds:?}"
    );
    // Both checker colours appear somewhere (the texture is sampled, not averaged).
    let (mut reds, mut blues) = (0, 0);
    for y in 0..h {
        for x in 0..w {
            let c = px(x, y);
            reds += usize::from(c[0] > c[2] + 60 && c[0] > c[1] + 60);
            blues += usize::from(c[2] > c[0] + 60 && c[2] > c[1] + 60);
        }
    }
    assert!(
        reds > 100 && blues > 100,
        "checker colours: {reds} red, {blues} blue"
    );

    // Every GPU backend equals the CPU oracle per pixel on the hit records (shaded view, so
    // shadow rays through the cut-out run too).
    if !gpu_available() {
        return;
    }
    let mut backends = vec!["pipeline"];
    if has_ray_query() {
        backends.push("query");
    }
    for b in backends {
        let gpu = dir.path().join(format!("{b}.aov"));
        let stats = render(&pkg, b, &gpu, &["--ao-samples", "0"]);
        assert!(
            stats["resources"]["texture_bytes"].as_u64().unwrap() >= want as u64,
            "{stats}"
        );
        let out = motu_ok(&["compare", s(&aov), s(&gpu), "--max-mismatch", "0.002"]);
        eprintln!("cpu vs {b}: {out}");
        // The GPU image shows the same texture and cut-out.
        let (_, _, g) = read_png(&gpu.with_extension("png"));
        let diff: u64 = g
            .iter()
            .zip(&rgba)
            .map(|(a, b)| u64::from(a.abs_diff(*b)))
            .sum();
        let mean = diff as f64 / g.len() as f64;
        assert!(
            mean < 3.0,
            "{b}: mean channel difference {mean} to the CPU image"
        );
        // Streaming: the textures (the checker's colours, the leaf's cut-out) arrive with the
        // meshes that sample them; the streamed frame equals the full build per pixel.
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
        let resident = st["stream"]["frames"][0]["resident_textures"]
            .as_u64()
            .unwrap_or_else(|| panic!("resident_textures in {st}"));
        assert_eq!(resident, 2, "the checker and the leaf's alpha: {st}");
        let out = motu_ok(&["compare", s(&gpu), s(&streamed), "--max-mismatch", "0"]);
        assert!(out.contains("(0 of "), "{out}");
        let (_, _, sp) = read_png(&streamed.with_extension("png"));
        assert!(sp == g, "{b}: the streamed image equals the full build's");
    }
}
