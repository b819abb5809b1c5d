use super::*;
use crate::sizes::{fit_linear, relative_error, BlasShape, TriangleGeometry, CURVE_NAMES};

/// The preset data files are exactly what the code writes for the presets it loads from them
/// (nothing in a file is ignored, lost or rounded), and hold every curve with its measurements.
#[test]
fn preset_data_files_load_whole_and_exact() {
    for (json, p, name) in [
        (LAVAPIPE_JSON, &*LAVAPIPE, "lavapipe"),
        (NVIDIA_H200_JSON, &*NVIDIA_H200, "nvidia-h200"),
    ] {
        assert_eq!(p.name, name);
        assert_eq!(p.to_json(), json, "{name}: the data file is canonical");
        assert_eq!(&ModelPreset::from_json(json).unwrap(), p);
        let measured: Vec<&str> = p.measured.iter().map(|(w, _)| w.as_str()).collect();
        assert_eq!(measured, CURVE_NAMES, "{name}");
        for what in CURVE_NAMES {
            assert!(!p.curve(what).unwrap().small.is_empty(), "{name} {what}");
        }
    }
    assert!(ModelPreset::from_json(&LAVAPIPE_JSON.replace("\"tlas\"", "\"tlass\"")).is_err());
}

/// Values the presets held as Rust tables before they became data (`presets.rs` at d24a56b),
/// to the last bit.
#[test]
fn preset_data_matches_the_former_rust_tables() {
    let l = &*LAVAPIPE;
    assert_eq!(l.blas_triangles.base_bytes, -16.000000000008598);
    assert_eq!(l.blas_triangles.bytes_per_item, 104.00000000000001);
    assert_eq!(l.blas_triangles.eval(256), 26608);
    assert_eq!(l.compaction_ratio, 1.0);
    assert_eq!(l.max_primitive_count, 16_777_215);
    let h = &*NVIDIA_H200;
    assert_eq!(h.blas_triangles.bytes_per_item, 91.73287136383334);
    assert_eq!(h.compaction_ratio, 0.84);
    assert_eq!(h.max_primitive_count, 536_870_911);
    let tlas_scratch = &h
        .measured
        .iter()
        .find(|(w, _)| w == "tlas_scratch")
        .unwrap()
        .1;
    assert_eq!(tlas_scratch.last(), Some(&(1_048_576, 71_582_208)));
}

#[test]
fn presets_grow_with_counts_and_are_found_by_name() {
    for p in *PRESETS {
        assert_eq!(preset(&p.name).map(|q| &q.name), Some(&p.name));
        let small = p.blas_sizes(&BlasShape::Triangles(vec![TriangleGeometry {
            vertex_count: 30,
            triangle_count: 10,
            opaque: true,
        }]));
        let big = p.blas_sizes(&BlasShape::Triangles(vec![TriangleGeometry {
            vertex_count: 30_000,
            triangle_count: 10_000,
            opaque: true,
        }]));
        assert!(big.size_bytes > 100 * small.size_bytes / 2, "{}", p.name);
        assert!(p.tlas_sizes(1000).size_bytes > p.tlas_sizes(10).size_bytes);
        assert!(p.compaction_ratio > 0.0 && p.compaction_ratio <= 1.0);
    }
    assert!(preset("nope").is_none());
}

#[test]
fn presets_match_their_recorded_driver_sizes() {
    for p in *PRESETS {
        assert!(p.measured.len() >= 8, "{}: every curve is recorded", p.name);
        for (what, points) in &p.measured {
            let curve = p.curve(what).expect("known curve");
            for &(n, measured) in points {
                let err = relative_error(curve.eval(n), measured);
                assert!(
                    err <= p.fitted_max_relative_error + 1e-4,
                    "{} {what} at {n}: model {} vs measured {measured} ({:.2}%)",
                    p.name,
                    curve.eval(n),
                    err * 100.0
                );
            }
            // The preset is what the fit gives on these points.
            let (refit, _) = fit_linear(points);
            assert_eq!(&refit, curve, "{} {what}", p.name);
        }
    }
}
