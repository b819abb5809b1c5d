use super::*;

#[test]
fn coarser_with_distance_and_clamped() {
    let p = LodParams {
        r_max_px: 100.0,
        ..Default::default()
    };
    let at = |t| select_lod(&p, 500.0, 1.0, 1.0, t, 5, RAY_PRIMARY, 0.0);
    assert_eq!(at(1.0), 0); // 500 px
    assert_eq!(at(5.0), 0); // exactly 100 px
    assert_eq!(at(10.0), 1); // 50 px
    assert_eq!(at(20.0), 2);
    assert_eq!(at(1e9), 4);
    let levels: Vec<u32> = (1..200).map(|t| at(t as f32)).collect();
    assert!(
        levels.windows(2).all(|w| w[0] <= w[1]),
        "monotonic: {levels:?}"
    );
}

#[test]
fn forced_bias_and_dither() {
    let p = LodParams {
        r_max_px: 100.0,
        forced_lod: 2,
        ..Default::default()
    };
    assert_eq!(select_lod(&p, 500.0, 1.0, 1.0, 1.0, 5, RAY_SHADOW, 0.0), 2);
    assert_eq!(
        select_lod(
            &LodParams { forced_lod: 9, ..p },
            500.0,
            1.0,
            1.0,
            1.0,
            3,
            0,
            0.0
        ),
        2
    );
    let q = LodParams {
        r_max_px: 100.0,
        shadow_bias: 1.0,
        ..Default::default()
    };
    assert_eq!(select_lod(&q, 500.0, 1.0, 1.0, 10.0, 5, RAY_SHADOW, 0.0), 2);
    // 1.5 levels: dithers between 1 and 2.
    let d = LodParams {
        r_max_px: 100.0 * 2f32.sqrt(),
        stochastic: 1,
        ..Default::default()
    };
    assert_eq!(
        select_lod(&d, 500.0, 1.0, 1.0, 10.0, 5, RAY_PRIMARY, 0.9),
        1
    );
    assert_eq!(
        select_lod(&d, 500.0, 1.0, 1.0, 10.0, 5, RAY_PRIMARY, 0.1),
        2
    );
    // A scaled instance: local radius 2 seen through a 2× scale is radius 1 in the world.
    assert_eq!(
        select_lod(
            &LodParams {
                r_max_px: 100.0,
                ..Default::default()
            },
            500.0,
            2.0,
            2.0,
            10.0,
            5,
            0,
            0.0
        ),
        1
    );
}
