use super::*;

#[test]
fn constant_spectrum_is_grey() {
    let rgb = spectrum_rgb(&[(300.0, 0.4), (800.0, 0.4)]).unwrap();
    for c in rgb {
        assert!((c - 0.4).abs() < 1e-5);
    }
    let ramp = spectrum_rgb(&[(400.0, 0.0), (700.0, 1.0)]).unwrap();
    assert!(ramp[0] > ramp[1] && ramp[1] > ramp[2]);
}

#[test]
fn blackbody_warm_and_cool() {
    let warm = blackbody_rgb(2700.0);
    assert!(warm[0] > warm[2]);
    assert_eq!(warm[0], 1.0);
    let cool = blackbody_rgb(12000.0);
    assert!(cool[2] > cool[0]);
    assert_eq!(blackbody_rgb(-5.0), [0.0; 3]);
}

#[test]
fn xyz_white() {
    let rgb = xyz_to_rgb([0.950_47, 1.0, 1.088_83]);
    for c in rgb {
        assert!((c - 1.0).abs() < 1e-3, "{rgb:?}");
    }
}

#[test]
fn spd_files() {
    assert_eq!(
        parse_spd(b"# c\n400 1\n500 2 # x\n"),
        Some(vec![(400.0, 1.0), (500.0, 2.0)])
    );
    assert_eq!(parse_spd(b"400"), None);
    assert_eq!(parse_spd(b"400 x"), None);
}
