use super::*;

#[test]
fn lod_keys_without_instance_lod_count_the_package_selectors() {
    let choice = LodChoice {
        instance: None,
        mode: "traversal",
        reason: "test",
        selector_pis: 7,
    };
    let stats = lod_stats(&choice);
    assert_eq!(stats.lod_mode, "traversal");
    assert_eq!(stats.lod_mode_reason, "test");
    assert_eq!(stats.lod_instances, 0);
    assert_eq!(stats.lod_traversal_selectors, 7);
}
