//! Issue 47 item 5's leftover: the denoiser's base-colour guide includes the texture's albedo.
//! A checker-textured ground (one mesh, one material: its constant colour cannot tell the
//! cells apart) rendered with `--denoise` keeps the contrast across the checker's edges on the
//! CPU and every GPU backend; with the material constant alone as the guide the filter blurred
//! them (the colours of two cells are close enough for its colour weight to mix them).

use motu_tests::{checker_scene, gpu_available, has_ray_query, motu_ok, s};
use std::path::Path;

fn read_png(path: &Path) -> Vec<u8> {
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut r = dec.read_info().unwrap();
    let mut buf = vec![0u8; r.output_buffer_size().unwrap()];
    let info = r.next_frame(&mut buf).unwrap();
    buf.truncate(info.buffer_size());
    buf
}

/// Whether each pixel's primary ray hit something (the AOV: a 32-byte header, then 16-byte
/// records whose first word is the mesh, `u32::MAX` for a miss).
fn read_hits(path: &Path) -> Vec<bool> {
    let bytes = std::fs::read(path).unwrap();
    bytes[32..]
        .chunks_exact(16)
        .map(|r| u32::from_le_bytes([r[0], r[1], r[2], r[3]]) != u32::MAX)
        .collect()
}

const W: usize = 64;
const H: usize = 36;

fn lum(p: &[u8], i: usize) -> f64 {
    0.2126 * f64::from(p[i * 4])
        + 0.7152 * f64::from(p[i * 4 + 1])
        + 0.0722 * f64::from(p[i * 4 + 2])
}

/// Mean luminance step (8-bit) of `img` between 4-neighbours on the ground that lie in
/// different checker cells (`light`: by the albedo view).
fn edge_contrast(img: &[u8], light: &[Option<bool>]) -> (f64, usize) {
    let (mut sum, mut n) = (0.0, 0);
    for y in 0..H {
        for x in 0..W {
            let i = y * W + x;
            for j in [(x + 1 < W).then(|| i + 1), (y + 1 < H).then(|| i + W)]
                .into_iter()
                .flatten()
            {
                if let (Some(a), Some(b)) = (light[i], light[j]) {
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

/// CPU, the pipeline backend streamed and the query backend's full build (each renders the
/// albedo view for its guide on its own path); the cells and the undenoised contrast come from
/// the CPU (the backends agree with it per pixel on the AOV, in colour within tolerance).
#[test]
fn denoising_keeps_texel_edges_on_every_backend() {
    let t0 = std::time::Instant::now();
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = checker_scene(d);
    let pkg = d.join("checker.motu");
    motu_ok(&["import", s(&scene), "-o", s(&pkg)]);
    let render = |tag: &str, extra: &[&str]| {
        let (png, aov) = (d.join(format!("{tag}.png")), d.join(format!("{tag}.aov")));
        let mut args = vec!["render", s(&pkg), "-o", s(&png), "--aov", s(&aov)];
        args.extend(["--width", "64", "--height", "36"]);
        args.extend_from_slice(extra);
        motu_ok(&args);
        (read_png(&png), read_hits(&aov))
    };
    let (albedo, hits) = render("albedo", &["--backend", "cpu", "--view", "albedo"]);
    // Texels 0.6 and 0.3 (sRGB 203 and 149): light cells above the midpoint.
    let light: Vec<Option<bool>> = (0..W * H)
        .map(|i| hits[i].then(|| lum(&albedo, i) > 176.0))
        .collect();
    let (plain, _) = render("plain", &["--backend", "cpu"]);
    let (before, edges) = edge_contrast(&plain, &light);
    assert!(
        edges >= 300,
        "the checker's edges are in view ({edges} pairs)"
    );
    assert!(
        before >= 20.0,
        "the cells differ in the shaded image ({before:.1} steps)"
    );
    let mut runs: Vec<(&str, Vec<&str>)> = vec![("cpu", vec!["--backend", "cpu"])];
    if gpu_available() {
        // The GPU's albedo view is the CPU's (docs/shading.md's tolerance between backends:
        // at most 2% of the channels more than two 8-bit steps apart).
        let (gpu_albedo, gpu_hits) = render(
            "albedo-pipeline",
            &["--backend", "pipeline", "--view", "albedo"],
        );
        assert_eq!(gpu_hits, hits);
        let off = albedo
            .iter()
            .zip(&gpu_albedo)
            .filter(|(a, b)| a.abs_diff(**b) > 2)
            .count();
        assert!(
            off * 50 <= albedo.len(),
            "the pipeline's albedo view differs from the CPU's on {off} channels"
        );
        runs.push(("pipeline-stream", vec!["--backend", "pipeline", "--stream"]));
        if has_ray_query() {
            runs.push(("query", vec!["--backend", "query"]));
        }
    }
    for (tag, mut args) in runs {
        args.push("--denoise");
        let (denoised, _) = render(tag, &args);
        let (after, _) = edge_contrast(&denoised, &light);
        eprintln!(
            "{tag}: edge contrast {before:.1} before, {after:.1} after denoising ({edges} pairs)"
        );
        // Kept: the guide separates the cells (with the material constant alone the filter
        // mixed them: 0.0 of 25.3 steps).
        assert!(
            after >= 0.8 * before,
            "{tag}: denoising blurred the texel edges: contrast {after:.1} of {before:.1} 8-bit steps"
        );
    }
    eprintln!(
        "denoising_keeps_texel_edges_on_every_backend: {:.1} s",
        t0.elapsed().as_secs_f64()
    );
}
