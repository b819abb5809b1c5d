use super::*;
use crate::shade::rand01;

const IDENTITY: [[f32; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

fn map_with_sun() -> Environment {
    let (w, h) = (32u32, 16u32);
    let mut t = vec![[0.1f32, 0.2, 0.4]; (w * h) as usize];
    t[3 * w as usize + 5] = [500.0, 480.0, 450.0];
    Environment::new(w, h, t, IDENTITY).unwrap()
}

#[test]
fn samples_follow_the_light_and_their_pdf_integrates_to_one() {
    let env = map_with_sun();
    let n = 4096;
    let mut sun = 0;
    // E[L cosθ-free / pdf] over the sphere = ∫ L dω: compare with the texel sum.
    let mut estimate = 0.0f64;
    for i in 0..n {
        let s = env.sample(rand01(i, 0, 0), rand01(i, 0, 1)).unwrap();
        assert!(s.pdf > 0.0);
        let len: f32 = s.world_dir.iter().map(|c| c * c).sum();
        assert!((len - 1.0).abs() < 1e-4);
        if s.radiance[0] > 100.0 {
            sun += 1;
        }
        estimate += luminance(s.radiance) as f64 / s.pdf as f64 / n as f64;
    }
    assert!(sun > n / 2, "the sun texel holds most of the light: {sun}");
    let (w, h) = (32usize, 16usize);
    let mut exact = 0.0f64;
    for r in 0..h {
        let t0 = PI as f64 * r as f64 / h as f64;
        let t1 = PI as f64 * (r + 1) as f64 / h as f64;
        let solid = 2.0 * std::f64::consts::PI / w as f64 * (t0.cos() - t1.cos());
        for c in 0..w {
            exact += luminance(env.texel(c, r)) as f64 * solid;
        }
    }
    assert!(
        (estimate - exact).abs() < 0.05 * exact,
        "{estimate} vs {exact}"
    );
}

#[test]
fn escaping_rays_see_the_map_in_its_orientation() {
    let env = map_with_sun();
    // +z is row 0's pole; the sun texel (column 5, row 3) lies at θ ≈ 3.5/16 π.
    let theta = PI * 3.5 / 16.0;
    let phi = 2.0 * PI * 5.5 / 32.0;
    let d = [
        theta.sin() * phi.cos(),
        theta.sin() * phi.sin(),
        theta.cos(),
    ];
    assert!(env.radiance_towards(d)[0] > 100.0);
    assert!(env.radiance_towards([0.0, 0.0, -1.0])[0] < 1.0);
    // Rotated: the light's +z is the world's +y.
    let rot = [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]];
    let mut t = vec![[0.0f32; 3]; 32 * 16];
    t[0] = [1.0; 3]; // a texel at the +z pole
    let e = Environment::new(32, 16, t, rot).unwrap();
    let s = e.sample(0.01, 0.01).unwrap();
    assert!(s.world_dir[1] > 0.9, "{:?}", s.world_dir);
}

#[test]
fn black_maps_do_not_sample() {
    let e = Environment::new(4, 2, vec![[0.0; 3]; 8], IDENTITY).unwrap();
    assert!(!e.sampleable() && e.sample(0.5, 0.5).is_none());
    assert!(Environment::new(4, 2, vec![[0.0; 3]; 7], IDENTITY).is_none());
    assert_eq!(e.gpu_words().len(), ENV_HEADER_WORDS + 3 + 2 * 5 + 8 * 3);
    assert!(std::ptr::eq(e.clone().intern(), e.intern()));
}

#[test]
fn find_interval_picks_the_interval_holding_u() {
    let cdf = [0.0, 0.25, 0.25, 0.75, 1.0];
    assert_eq!(find_interval(&cdf, 0.0), 0);
    assert_eq!(find_interval(&cdf, 0.3), 2);
    assert_eq!(find_interval(&cdf, 0.25), 2);
    assert_eq!(find_interval(&cdf, 0.99), 3);
}
