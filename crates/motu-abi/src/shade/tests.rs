use super::*;

#[test]
fn mips_and_sampling() {
    let t = TextureRecord {
        texel_offset: 0,
        width: 4,
        height: 2,
        mip_count: 3,
    };
    assert_eq!(t.texel_count(), 8 + 2 + 1);
    assert_eq!(mip_level(0.5, 3), 0);
    assert_eq!(mip_level(2.5, 3), 1);
    assert_eq!(mip_level(1000.0, 3), 2);
    // Level 0 all red, level 1 green, level 2 blue.
    let mut texels = vec![0xff00_00ff; 8];
    texels.extend([0xff00_ff00; 2]);
    texels.push(0xffff_0000);
    let red = sample_texture(&t, &texels, [0.3, 0.7], 0);
    assert!((red[0] - 1.0).abs() < 1e-6 && red[1] == 0.0 && red[3] == 1.0);
    assert!(sample_texture(&t, &texels, [0.3, 0.7], 1)[1] > 0.999);
    assert!(sample_texture(&t, &texels, [-4.3, 9.7], 2)[2] > 0.999);
}

#[test]
fn random_numbers_are_uniform_ish() {
    let n = 4096;
    let mean: f32 = (0..n).map(|i| rand01(i, 3, 1)).sum::<f32>() / n as f32;
    assert!((mean - 0.5).abs() < 0.02, "{mean}");
    assert_ne!(rand01(1, 0, 0), rand01(1, 1, 0));
    assert_ne!(rand01(1, 0, 0), rand01(1, 0, 1));
}

#[test]
fn cosine_directions_stay_in_the_hemisphere() {
    for n in [
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
        [0.6, 0.0, 0.8],
        [0.0, -1.0, 0.0],
    ] {
        for i in 0..64 {
            let d = cosine_direction(n, rand01(i, 0, 0), rand01(i, 0, 1));
            let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            assert!((len - 1.0).abs() < 1e-4, "{d:?}");
            assert!(
                d[0] * n[0] + d[1] * n[1] + d[2] * n[2] >= 0.0,
                "{d:?} vs {n:?}"
            );
        }
    }
    assert!(shininess(0.0) > shininess(0.5) && shininess(1.0) >= 1.0);
}

#[test]
fn default_key_light_matches_the_sun() {
    let (l, n) = Shading::default().frame_lights([0.0, 2.0, 0.0], 0.8);
    assert_eq!(n, 1);
    assert_eq!(l[0].kind, LIGHT_DISTANT);
    assert_eq!(l[0].world_direction, [0.0, -1.0, 0.0]);
    assert!((l[0].radiance[0] / std::f32::consts::PI - 0.8).abs() < 1e-6);
}

#[test]
fn rgb9e5_round_trips_within_its_precision() {
    for c in [
        [0.0, 0.0, 0.0],
        [1.0, 0.5, 0.25],
        [1e-6, 3e-5, 2e-7],
        [1234.5, 0.1, 77.0],
        [0.999, 0.999, 0.999],
        [1e9, -1.0, f32::NAN],
    ] {
        let d = decode_rgb9e5(encode_rgb9e5(c));
        let m = c
            .iter()
            .cloned()
            .filter(|v| v.is_finite())
            .fold(0.0f32, f32::max)
            .min(65408.0);
        for i in 0..3 {
            let want = if c[i] > 0.0 { c[i].min(65408.0) } else { 0.0 };
            assert!((d[i] - want).abs() <= m / 512.0 + 1e-30, "{c:?} -> {d:?}");
        }
    }
    assert_eq!(
        decode_rgb9e5(encode_rgb9e5([0.5, 0.25, 1.0])),
        [0.5, 0.25, 1.0]
    );
}

#[test]
fn auto_exposure_brings_the_log_average_to_middle_grey() {
    let dark = [[0.01f32; 3]; 16];
    let ev = auto_exposure_ev(dark.iter().copied());
    assert!((ev - (0.18f32 / 0.01).log2()).abs() < 0.05, "{ev}");
    // Black pixels do not drag the exposure up.
    let half_black = dark.iter().copied().chain([[0.0f32; 3]; 16]);
    assert!((auto_exposure_ev(half_black) - ev).abs() < 1e-4);
    let bright = [[40.0f32; 3]; 16];
    assert!(auto_exposure_ev(bright.iter().copied()) < -7.0);
    assert_eq!(auto_exposure_ev([[0.0f32; 3]; 4].into_iter()), 0.0);
    let mut px: Vec<u8> = dark
        .iter()
        .flat_map(|c| encode_rgb9e5(*c).to_le_bytes())
        .collect();
    let ev = resolve_auto_exposure(&mut px);
    assert!(ev > 4.0);
    // Middle grey after exposure: sRGB ≈ 118.
    assert!((110..=125).contains(&px[0]), "{}", px[0]);
    assert_eq!(px[3], 255);
}

#[test]
fn tone_map_is_srgb_after_exposure() {
    assert_eq!(tone_map([0.0, 1.0, 2.0], 1.0), [0, 255, 255]);
    assert_eq!(tone_map([0.5, 0.5, 0.5], 0.5), tone_map([0.25; 3], 1.0));
    assert_eq!(tone_map([0.2159; 3], 1.0), [128; 3]);
}
