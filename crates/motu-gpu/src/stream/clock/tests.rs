use std::time::{Duration, Instant};

use super::{Ewma, FrameClock};

#[test]
fn an_average_takes_its_first_sample_then_moves_a_quarter_of_the_way() {
    let mut e = Ewma::default();
    assert_eq!(e.get(), None);
    e.note(8.0);
    assert_eq!(e.get(), Some(8.0));
    e.note(16.0);
    assert_eq!(e.get(), Some(10.0));
    // Samples a clock could give across a suspend are not taken.
    e.note(-1.0);
    e.note(f64::NAN);
    e.note(f64::INFINITY);
    assert_eq!(e.get(), Some(10.0));
    // A lasting change is followed: within 1% of it after 16 samples.
    for _ in 0..16 {
        e.note(2.0);
    }
    assert!((e.get().unwrap() - 2.0).abs() < 0.1, "{e:?}");
}

#[test]
fn time_left_is_the_frame_less_elapsed_less_the_tail_estimate() {
    let mut c = FrameClock::default();
    // No tail measured yet: the frame less what elapsed.
    assert_eq!(c.time_left_ms(50.0, 20.0), 30.0);
    assert_eq!(c.time_left_ms(50.0, 60.0), -10.0);
    // A frame whose last build decision came 6 ms before its end.
    let t0 = Instant::now();
    c.begin(t0);
    c.decided(Some(t0));
    c.end(t0 + Duration::from_millis(6));
    assert_eq!(c.time_left_ms(50.0, 20.0), 24.0);
    assert_eq!(c.time_left_ms(50.0, 44.0), 0.0);
    // A frame whose decision a prefetch or probe followed samples no tail.
    c.begin(t0);
    c.decided(Some(t0));
    c.decided(None);
    c.end(t0 + Duration::from_millis(100));
    assert_eq!(c.time_left_ms(50.0, 20.0), 24.0);
    // Nor does a frame with no build decision.
    c.begin(t0);
    c.end(t0 + Duration::from_millis(100));
    assert_eq!(c.time_left_ms(50.0, 20.0), 24.0);
}

#[test]
fn build_groups_are_sized_by_the_measured_cost_of_a_triangle() {
    let mut c = FrameClock::default();
    // Before any build was measured: one BLAS when time is left (its build is the sample),
    // none when none is, one anyway when the frame must progress.
    assert_eq!(c.blases_within([1000, 1000], 10.0, 0.0, false), 1);
    assert_eq!(c.blases_within([1000, 1000], -1.0, 0.0, false), 0);
    assert_eq!(c.blases_within([1000, 1000], -1.0, 0.0, true), 1);
    assert_eq!(c.blases_within([], 10.0, 0.0, true), 0);
    // 4 ms for 2M triangles: 2,000 ns a thousand triangles, 2 ms a million.
    c.note_build(4.0, 2_000_000);
    // 9 ms left: 2 + 2 + 4 fit, the next 2 does not; with 10, it does.
    let tris = [1_000_000, 1_000_000, 2_000_000, 1_000_000];
    assert_eq!(c.blases_within(tris, 9.0, 0.0, false), 3);
    assert_eq!(c.blases_within(tris, 10.0, 0.0, false), 4);
    // Time kept for a piece rebuild comes off.
    assert_eq!(c.blases_within(tris, 9.0, 5.0, false), 2);
    // Everything fits.
    assert_eq!(c.blases_within(tris, 100.0, 0.0, false), 4);
    // Nothing fits: none, or one when the frame must progress.
    assert_eq!(c.blases_within(tris, 1.0, 0.0, false), 0);
    assert_eq!(c.blases_within(tris, 1.0, 0.0, true), 1);
    assert_eq!(c.blases_within(tris, -5.0, 0.0, true), 1);
    // Slower groups make smaller ones: a group at 10 ms a million moves the average a
    // quarter of the way, 2 + (10 − 2) / 4 = 4 ms a million.
    c.note_build(10.0, 1_000_000);
    assert_eq!(c.blases_within(tris, 9.0, 0.0, false), 2);
    // A group of no triangles is no sample.
    c.note_build(1000.0, 0);
    assert_eq!(c.blases_within(tris, 9.0, 0.0, false), 2);
}

#[test]
fn stale_pieces_and_probes_fit_by_their_measured_time() {
    let mut c = FrameClock::default();
    // Before a rebuild was measured: one when time is left.
    assert_eq!(c.pieces_within(5.0, false), 1);
    assert_eq!(c.pieces_within(0.0, false), 0);
    assert_eq!(c.pieces_within(-3.0, true), 1);
    // A group of 3 pieces in 24 ms: 8 ms a piece.
    c.note_pieces(24.0, 3);
    assert_eq!(c.piece_estimate_ms(), 8.0);
    assert_eq!(c.pieces_within(17.0, false), 2);
    assert_eq!(c.pieces_within(7.9, false), 0);
    assert_eq!(c.pieces_within(7.9, true), 1);
    // A rebuild of no pieces is no sample.
    c.note_pieces(100.0, 0);
    assert_eq!(c.piece_estimate_ms(), 8.0);
    // The probe: any time left before it was measured, then its estimate.
    assert!(c.probe_fits(1.0));
    assert!(!c.probe_fits(0.0));
    c.note_probe(6.0);
    assert!(c.probe_fits(6.0));
    assert!(!c.probe_fits(5.0));
}
