use super::*;
use motu_abi::aov::AovRecord;

const W: u32 = 48;
const H: u32 = 32;

/// A camera at the origin looking down -z at two walls facing it: the left half of the image
/// a near wall (z = -4, mesh 1, bright), the right half a far one (z = -9, mesh 2, dark); the
/// top rows miss (sky). The true linear colours, and the AOV and guide.
fn two_walls() -> (CameraParams, Aov, Vec<[f32; 3]>) {
    let cam = CameraParams::new(
        [0.0, 0.0, 0.0].into(),
        [0.0, 0.0, -1.0].into(),
        [0.0, 1.0, 0.0].into(),
        50.0,
        false,
        W,
        H,
    );
    let mut aov = Aov::new(W, H);
    let mut truth = vec![[0.0; 3]; (W * H) as usize];
    for y in 0..H {
        for x in 0..W {
            let i = (y * W + x) as usize;
            if y < 4 {
                truth[i] = [0.3, 0.5, 0.9];
                continue;
            }
            let d = cam.primary_dir(x, y, 0.5, 0.5);
            let (mesh, z, c) = if x < W / 2 {
                (1, 4.0, [0.6, 0.55, 0.5])
            } else {
                (2, 9.0, [0.08, 0.1, 0.12])
            };
            aov.records[i] = AovRecord {
                mesh,
                primitive: 0,
                t: z / -d.z,
                lod: 0,
                _pad: 0,
                traces: 1,
            };
            truth[i] = c;
        }
    }
    (cam, aov, truth)
}

fn encode(c: &[[f32; 3]]) -> Vec<u8> {
    c.iter()
        .flat_map(|c| {
            let e = motu_abi::shade::tone_map(*c, 1.0);
            [e[0], e[1], e[2], 255]
        })
        .collect()
}

fn linear(px: &[u8], i: usize) -> [f32; 3] {
    [0, 1, 2].map(|k| motu_abi::shade::srgb_to_linear(f32::from(px[i * 4 + k]) / 255.0))
}

fn mse(px: &[u8], truth: &[[f32; 3]], aov: &Aov) -> f64 {
    let mut e = 0.0f64;
    let mut n = 0;
    for (i, t) in truth.iter().enumerate() {
        if aov.records[i].mesh == MISS {
            continue;
        }
        let c = linear(px, i);
        e += (0..3).map(|k| ((c[k] - t[k]) as f64).powi(2)).sum::<f64>();
        n += 1;
    }
    e / n as f64
}

#[test]
fn the_filter_removes_noise_and_keeps_the_silhouette_and_the_sky() {
    let (cam, aov, truth) = two_walls();
    let albedo = |m: u32| if m == 1 { [0.8; 3] } else { [0.2; 3] };
    let guide = guide_from_aov(&aov, &cam, albedo);
    // The rebuilt normals face the camera (+z) on both walls.
    for (g, r) in guide.iter().zip(&aov.records) {
        if r.mesh != MISS {
            assert!(g.normal[2] > 0.99, "{:?}", g.normal);
        }
    }
    // Noisy: each channel off by up to ±60% (a few samples of AO and sky rays).
    let mut seed = 7u32;
    let noisy: Vec<[f32; 3]> = truth
        .iter()
        .zip(&aov.records)
        .map(|(t, r)| {
            if r.mesh == MISS {
                return *t;
            }
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let f = 1.0 + 1.2 * ((seed >> 8) as f32 / (1u32 << 24) as f32 - 0.5);
            t.map(|c| c * f)
        })
        .collect();
    let mut px = encode(&noisy);
    let before = mse(&px, &truth, &aov);
    let sky_before: Vec<u8> = px[..(4 * W * 4) as usize].to_vec();
    let st = denoise_rgba8(
        &mut px,
        W,
        H,
        &guide,
        pixel_footprint(&cam),
        &DenoiseOptions::default(),
    );
    let after = mse(&px, &truth, &aov);
    assert!(after * 4.0 < before, "error {before:.5} → {after:.5}");
    assert_eq!(st.filtered_pixels, u64::from(W * (H - 4)));
    assert_eq!(
        &px[..(4 * W * 4) as usize],
        &sky_before[..],
        "the sky changed"
    );
    // Across the silhouette the two walls keep their contrast (nothing bled over): on average
    // nearly all of it, each row (some noise stays where half the taps are on the other wall)
    // at least half.
    let step = 0.6 - 0.08;
    let mut sum = 0.0;
    for y in 4..H {
        let l = linear(&px, (y * W + W / 2 - 1) as usize)[0];
        let r = linear(&px, (y * W + W / 2) as usize)[0];
        assert!(l - r > 0.5 * step, "row {y}: {l} | {r}");
        sum += l - r;
    }
    let mean = sum / (H - 4) as f32;
    assert!(mean > 0.85 * step, "mean step {mean} of {step}");
}

#[test]
fn a_normal_edge_on_one_mesh_keeps_its_step() {
    // One mesh folded into a crease: the guide's normals differ across it, so the filter keeps
    // the two faces' colours apart even with equal base colours.
    let (cam, mut aov, _) = two_walls();
    for y in 4..H {
        for x in W / 2..W {
            let i = (y * W + x) as usize;
            let d = cam.primary_dir(x, y, 0.5, 0.5);
            // The plane through the near wall's edge, turned 60° about y: z = -4 - (x' ) tan60.
            let x0 = 4.0
                * (cam.primary_dir(W / 2, y, 0.0, 0.5).x / -cam.primary_dir(W / 2, y, 0.0, 0.5).z);
            let k = 3f32.sqrt();
            // Ray: p = t d; on the plane z = -4 - k (p.x - x0).
            let t = (-4.0 + k * x0) / (d.z + k * d.x);
            aov.records[i].mesh = 1;
            aov.records[i].t = t;
        }
    }
    let guide = guide_from_aov(&aov, &cam, |_| [0.5; 3]);
    let (l, r) = (
        &guide[(10 * W + 5) as usize],
        &guide[(10 * W + W - 5) as usize],
    );
    assert!(
        dot(l.normal, r.normal) < 0.7,
        "{:?} {:?}",
        l.normal,
        r.normal
    );
    let colours: Vec<[f32; 3]> = (0..W * H)
        .map(|i| if i % W < W / 2 { [0.5; 3] } else { [0.1; 3] })
        .collect();
    let mut px = encode(&colours);
    denoise_rgba8(
        &mut px,
        W,
        H,
        &guide,
        pixel_footprint(&cam),
        &DenoiseOptions::default(),
    );
    for y in 6..H - 2 {
        let l = linear(&px, (y * W + W / 2 - 2) as usize)[0];
        let r = linear(&px, (y * W + W / 2 + 1) as usize)[0];
        assert!(l - r > 0.3, "row {y}: {l} | {r}");
    }
}

/// The albedo view's colours replace the material constant where its hit is the frame's, and
/// only there (a different hit, a miss or a size mismatch keep the constant).
#[test]
fn texture_albedo_fills_the_guide_where_the_hits_agree() {
    let (cam, aov, _) = two_walls();
    let mut guide = guide_from_aov(&aov, &cam, |_| [0.5; 3]);
    let mut albedo_aov = aov.clone();
    let hit = (4 * W) as usize; // the first hit row's first pixel
    let other = hit + 1;
    albedo_aov.records[other].primitive = 7; // not the frame's hit
    let albedo: Vec<u8> = (0..W * H).flat_map(|_| [255u8, 0, 0, 255]).collect();
    let taken = add_texture_albedo(&mut guide, &aov, &albedo, &albedo_aov);
    let hits = aov.records.iter().filter(|r| r.mesh != MISS).count() as u64;
    assert_eq!(taken, hits - 1);
    assert_eq!(guide[hit].albedo, [1.0, 0.0, 0.0]);
    assert_eq!(guide[other].albedo, [0.5; 3]);
    assert_eq!(guide[0].albedo, [0.0; 3], "a miss keeps no albedo");
    let mut g2 = guide_from_aov(&aov, &cam, |_| [0.5; 3]);
    assert_eq!(
        add_texture_albedo(&mut g2, &aov, &albedo[4..], &albedo_aov),
        0
    );
}
