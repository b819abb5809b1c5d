//! Issue 47 item 5's leftover: the denoiser's base-colour guide includes the texture's albedo.
//! A checker-textured ground (one mesh, one material: its constant colour cannot tell the
//! cells apart) rendered with `--denoise` keeps the contrast across the checker's edges on the
//! CPU and every GPU backend; with the material constant alone as the guide the filter blurred
//! them (the colours of two cells are close enough for its colour weight to mix them).

use motu_tests::{gpu_available, has_ray_query, motu_ok, s};
use std::path::Path;

/// 16×16 RGB checker of 2×2-texel cells, two greys of moderate contrast (PFM: little endian).
fn write_checker_pfm(path: &Path) {
    let mut bytes = b"PF\n16 16\n-1.0\n".to_vec();
    for y in 0..16 {
        for x in 0..16 {
            let v = if (x / 2 + y / 2) % 2 == 0 {
                0.6f32
            } else {
                0.3
            };
            for _ in 0..3 {
                bytes.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    std::fs::write(path, bytes).unwrap();
}

fn write_scene(dir: &Path) -> std::path::PathBuf {
    write_checker_pfm(&dir.join("checker.pfm"));
    let scene = dir.join("scene.pbrt");
    std::fs::write(
        &scene,
        r#"LookAt 0 8 0  0 0 0  0 0 1
Camera "perspective" "float fov" [45]
WorldBegin
LightSource "distant" "point from" [0.3 10 0.2] "point to" [0 0 0] "rgb L" [2.5 2.5 2.5]
Texture "checks" "spectrum" "imagemap" "string filename" "checker.pfm"
AttributeBegin
  Material "matte" "texture Kd" "checks"
  Shape "trianglemesh" "point P" [-3 0 -3  3 0 -3  3 0 3  -3 0 3]
    "float uv" [0 0  1 0  1 1  0 1] "integer indices" [0 1 2  0 2 3]
AttributeEnd
"#,
    )
    .unwrap();
    scene
}

fn read_png(path: &Path) -> Vec<u8> {
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut r = dec.read_info().unwrap();
    let mut buf = vec![0u8; r.output_buffer_size().unwrap()];
    let info = r.next_frame(&mut buf).unwrap();
    buf.truncate(info.buffer_size());
    buf
}

const W: usize = 64;
const H: usize = 36;

/// Mean luminance step (8-bit) between 4-neighbours that lie in different checker cells (by
/// the albedo view `albedo`), both on the ground.
fn edge_contrast(img: &[u8], albedo: &[u8]) -> (f64, usize) {
    let lum = |p: &[u8], i: usize| {
        0.2126 * f64::from(p[i * 4])
            + 0.7152 * f64::from(p[i * 4 + 1])
            + 0.0722 * f64::from(p[i * 4 + 2])
    };
    // Ground texels are greys (sRGB 203 and 149): light cells above the midpoint, dark below; the sky
    // (blue-ish, not grey) is left out.
    let class = |i: usize| {
        let (r, g, b) = (albedo[i * 4], albedo[i * 4 + 1], albedo[i * 4 + 2]);
        let grey = r.abs_diff(g) <= 2 && g.abs_diff(b) <= 2;
        grey.then_some(lum(albedo, i) > 176.0)
    };
    let (mut sum, mut n) = (0.0, 0);
    for y in 0..H {
        for x in 0..W {
            let i = y * W + x;
            for j in [(x + 1 < W).then(|| i + 1), (y + 1 < H).then(|| i + W)]
                .into_iter()
                .flatten()
            {
                if let (Some(a), Some(b)) = (class(i), class(j)) {
                    if a != b {
                        sum += (lum(img, i) - lum(img, j)).abs();
                        n += 1;
                    }
                }
            }
        }
    }
    (sum / n.max(1) as f64, n)
}

#[test]
fn denoising_keeps_texel_edges_on_every_backend() {
    let t0 = std::time::Instant::now();
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = write_scene(d);
    let pkg = d.join("checker.motu");
    motu_ok(&["import", s(&scene), "-o", s(&pkg)]);
    let mut backends = vec!["cpu"];
    if gpu_available() {
        backends.push("pipeline");
        if has_ray_query() {
            backends.push("query");
        }
    }
    for b in backends {
        let png = |tag: &str, extra: &[&str]| {
            let out = d.join(format!("{b}-{tag}.png"));
            let mut args = vec!["render", s(&pkg), "-o", s(&out), "--backend", b];
            args.extend(["--width", "64", "--height", "36"]);
            args.extend_from_slice(extra);
            motu_ok(&args);
            read_png(&out)
        };
        let albedo = png("albedo", &["--view", "albedo"]);
        let plain = png("plain", &[]);
        let denoised = png("denoised", &["--denoise"]);
        let (before, edges) = edge_contrast(&plain, &albedo);
        let (after, _) = edge_contrast(&denoised, &albedo);
        assert!(
            edges >= 100,
            "{b}: the checker's edges are in view ({edges} pairs)"
        );
        assert!(
            before >= 20.0,
            "{b}: the cells differ in the shaded image ({before:.1} steps)"
        );
        // Kept: the guide separates the cells (the material constant alone gave ~0.5).
        assert!(
            after >= 0.9 * before,
            "{b}: denoising blurred the texel edges: contrast {after:.1} of {before:.1} 8-bit steps"
        );
    }
    eprintln!(
        "denoising_keeps_texel_edges_on_every_backend: {:.1} s",
        t0.elapsed().as_secs_f64()
    );
}
