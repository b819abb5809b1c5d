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
