use super::*;

/// The stored report keeps the keys `motu info` reads from it (`motu_pack::PackageInfo`).
#[test]
fn stored_report_has_the_keys_info_reads() {
    let r = motu_compile::CompileReport {
        tlas_levels: 3,
        split_tlases: 4,
        max_blas_triangles: 5,
        partitioned_meshes: 6,
        partition_clusters: 7,
        baked_prototypes: 8,
        inlined_prototypes: 9,
        ..Default::default()
    };
    let v = serde_json::to_value(CompileReport::from(&r)).unwrap();
    for (key, want) in [
        ("tlas_levels", 3),
        ("split_tlases", 4),
        ("max_blas_triangles", 5),
        ("partitioned_meshes", 6),
        ("partition_clusters", 7),
        ("baked_prototypes", 8),
        ("inlined_prototypes", 9),
    ] {
        assert_eq!(v[key], want, "{key}: {v}");
    }
    assert!(v["phases"]["analyze_ms"].is_f64(), "{v}");
}
