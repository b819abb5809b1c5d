use super::*;

fn frame(level: u8, ev: f32) -> RenderOutput {
    let mut out = RenderOutput {
        aov: Aov::new(2, 1),
        rgba8: vec![level, level, level, 255, 0, 0, 0, 255],
        stats: Default::default(),
    };
    out.stats.exposure_ev = ev;
    out
}

fn camera() -> CameraParams {
    CameraParams::new(
        [0.0, 0.0, 0.0].into(),
        [0.0, 0.0, -1.0].into(),
        [0.0, 1.0, 0.0].into(),
        45.0,
        false,
        2,
        1,
    )
}

fn fixed() -> RenderOptions {
    let mut o = RenderOptions::default();
    o.shading.auto_exposure = false;
    o
}

#[test]
fn frames_at_rest_average_and_any_change_starts_again() {
    let mut acc = Accumulator::default();
    let (cam, opts) = (camera(), fixed());
    assert_eq!(acc.first_sample(&cam, &opts, &[true], false), Some(0));
    let mut a = frame(255, 0.0);
    a.aov.records[0].mesh = 7;
    assert_eq!(acc.add(&mut a, &opts), 1);
    assert_eq!(a.rgba8[0], 255);
    assert_eq!(acc.first_sample(&cam, &opts, &[true], false), Some(1));
    // Linear 1 and 0: the mean is linear 0.5 (sRGB 188), not the sRGB mean.
    let mut b = frame(0, 0.0);
    assert_eq!(acc.add(&mut b, &opts), 2);
    assert_eq!(b.rgba8[0], tone_map([0.5; 3], 1.0)[0]);
    assert_eq!(b.aov.records[0].mesh, 7, "the run's first AOV is kept");
    // A frame at another exposure is taken back to linear with its own.
    let mut c = frame(255, 1.0); // linear 0.5 before its exposure
    acc.add(&mut c, &opts);
    assert_eq!(c.rgba8[0], tone_map([0.5; 3], 1.0)[0]);
    // Anything changed: the camera, an option, the elements, the LOD mode, the view.
    let mut moved = cam;
    moved.world_eye[0] += 0.1;
    assert_eq!(acc.first_sample(&moved, &opts, &[true], false), Some(0));
    acc.add(&mut frame(10, 0.0), &opts);
    let mut spp = opts;
    spp.shading.spp = 4;
    assert_eq!(acc.first_sample(&moved, &spp, &[true], false), Some(0));
    acc.add(&mut frame(10, 0.0), &spp);
    assert_eq!(acc.samples(), 4, "a frame of 4 spp adds 4 samples");
    assert_eq!(acc.first_sample(&moved, &spp, &[true], false), Some(4));
    assert_eq!(acc.first_sample(&moved, &spp, &[false], false), Some(0));
    acc.add(&mut frame(10, 0.0), &spp);
    assert_eq!(acc.first_sample(&moved, &spp, &[false], true), Some(0));
    let mut ids = spp;
    ids.view = View::Ids;
    assert_eq!(acc.first_sample(&moved, &ids, &[false], true), None);
    assert_eq!(acc.samples(), 0);
}

/// The rayon accumulation and tone map give the sequential formulas' bytes and exposure (auto
/// exposure over the run's mean) to the bit, over a large random image and two frames.
#[test]
fn parallel_accumulation_equals_the_sequential_formulas() {
    let (w, h) = (333u32, 97u32);
    let n = (w * h) as usize;
    let mut state = 0x1234_5678u32;
    let mut bytes = || {
        (0..n * 4)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 17;
                state ^= state << 5;
                (state >> 24) as u8
            })
            .collect::<Vec<u8>>()
    };
    let (f0, f1) = (bytes(), bytes());
    let mut cam = camera();
    (cam.width, cam.height) = (w, h);
    let mut opts = RenderOptions::default();
    opts.shading.auto_exposure = true;
    let mut acc = Accumulator::default();
    let mut out = |rgba8: &Vec<u8>, ev: f32| {
        acc.first_sample(&cam, &opts, &[true], false);
        let mut f = RenderOutput {
            aov: Aov::new(w, h),
            rgba8: rgba8.clone(),
            stats: Default::default(),
        };
        f.stats.exposure_ev = ev;
        acc.add(&mut f, &opts);
        f
    };
    let (a, b) = (out(&f0, 0.5), out(&f1, -1.0));
    // The formulas, one pixel after another.
    let mut sum = vec![[0.0f32; 3]; n];
    for (frame, ev) in [(&f0, 0.5f32), (&f1, -1.0)] {
        let inv = (-ev).exp2();
        for (s, p) in sum.iter_mut().zip(frame.chunks_exact(4)) {
            for (c, v) in s.iter_mut().zip(&p[..3]) {
                *c += srgb_to_linear(f32::from(*v) / 255.0) * inv;
            }
        }
    }
    let mean: Vec<[f32; 3]> = sum.iter().map(|s| s.map(|c| c * 0.5)).collect();
    let ev = motu_abi::shade::auto_exposure_ev(mean.iter().copied());
    assert_eq!(b.stats.exposure_ev.to_bits(), ev.to_bits());
    let want: Vec<u8> = mean
        .iter()
        .flat_map(|c| {
            let [r, g, b] = tone_map(*c, ev.exp2());
            [r, g, b, 255]
        })
        .collect();
    assert!(
        b.rgba8 == want,
        "the mean's bytes differ from the formulas'"
    );
    assert_ne!(a.rgba8, b.rgba8, "the second frame changed the mean");
}
