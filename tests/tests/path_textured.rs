//! A camera path of one camera renders exactly what a plain render of that camera does, on a
//! textured scene, on the CPU and both GPU backends, shaded and albedo (AOV and PNG).
//!
//! The path renderer of a full build (`motu_gpu::LiveRenderer`: `render --camera-path`, and
//! every `motu view` frame) once left the frame's shading-table address at 0, so its frames lost
//! image textures, shading normals, uvs and alpha cut-outs while `render` kept them: an
//! untextured scene gave identical images, a textured one did not (CI's denoise.rs caught the
//! albedo view). The address is now a parameter of every renderer's frame parameters.

use motu_tests::{checker_scene, gpu_available, has_ray_query, motu, motu_ok, s};
use std::path::Path;

fn read_png(path: &Path) -> Vec<u8> {
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut r = dec.read_info().unwrap();
    let mut buf = vec![0u8; r.output_buffer_size().unwrap()];
    let info = r.next_frame(&mut buf).unwrap();
    buf.truncate(info.buffer_size());
    buf
}

/// Pixels of `rgba8` whose luminance is above and below the checker's midpoint (texels 0.6
/// and 0.3: sRGB 203 and 149 in the albedo view).
fn light_and_dark(rgba8: &[u8]) -> (usize, usize) {
    let lum: Vec<f64> = rgba8
        .chunks_exact(4)
        .map(|p| 0.2126 * f64::from(p[0]) + 0.7152 * f64::from(p[1]) + 0.0722 * f64::from(p[2]))
        .collect();
    (
        lum.iter().filter(|l| **l > 176.0).count(),
        lum.iter().filter(|l| **l < 176.0).count(),
    )
}

#[test]
fn a_one_camera_path_renders_the_plain_renders_textured_image() {
    let t0 = std::time::Instant::now();
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = checker_scene(d);
    let pkg = d.join("checker.motu");
    motu_ok(&["import", s(&scene), "-o", s(&pkg)]);
    let path = d.join("one.json");
    std::fs::write(
        &path,
        format!(
            r#"{{"format": "motu-camera-path", "version": 1, "width": 64, "height": 36,
               "frames": [{}]}}"#,
            motu_tests::CHECKER_CAMERA_POSE
        ),
    )
    .unwrap();
    let render = |tag: &str, extra: &[&str]| {
        let (png, aov) = (d.join(format!("{tag}.png")), d.join(format!("{tag}.aov")));
        let mut args = vec!["render", s(&pkg), "-o", s(&png), "--aov", s(&aov)];
        args.extend(["--width", "64", "--height", "36"]);
        args.extend_from_slice(extra);
        motu_ok(&args);
        (read_png(&png), aov)
    };
    let mut backends = vec!["cpu"];
    if gpu_available() {
        backends.push("pipeline");
        if has_ray_query() {
            backends.push("query");
        }
    }
    for backend in &backends {
        for view in ["shaded", "albedo"] {
            let tag = format!("{backend}-{view}");
            let common = ["--backend", backend, "--view", view];
            let (plain, plain_aov) = render(&format!("{tag}-plain"), &common);
            let mut args = common.to_vec();
            args.extend(["--camera-path", s(&path)]);
            let (one, one_aov) = render(&format!("{tag}-path"), &args);
            let out = motu(&["compare", s(&plain_aov), s(&one_aov), "--max-mismatch", "0"]);
            assert!(
                out.status.success(),
                "{tag}: the one-camera path's AOV differs from the plain render's: {}{}",
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            );
            let differing = plain.iter().zip(&one).filter(|(a, b)| a != b).count();
            assert_eq!(
                differing, 0,
                "{tag}: the one-camera path's PNG differs from the plain render's on {differing} channels"
            );
            // Not vacuous: both show the texture (the cells' two colours), which the material
            // constant alone cannot.
            if view == "albedo" {
                let (light, dark) = light_and_dark(&one);
                assert!(
                    light > 300 && dark > 300,
                    "{tag}: the checker is not in the image ({light} light, {dark} dark pixels)"
                );
            }
        }
    }
    eprintln!(
        "a_one_camera_path_renders_the_plain_renders_textured_image ({}): {:.1} s",
        backends.join(", "),
        t0.elapsed().as_secs_f64()
    );
}
