use super::{
    evicted_causes, file_stamp, first_pass_misses, package_changed_hint, working_set_note,
};

/// Issue 49: a package replaced under a CPU render said "mesh record 181: triangle 0 uses
/// vertex 1523 of 12" without the file or the likely cause.
#[test]
fn regression_package_changed_under_a_render_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("p.motu");
    std::fs::write(&p, b"first package").unwrap();
    let opened = file_stamp(&p);
    let cause = || anyhow::anyhow!("mesh record 181: triangle 0 uses vertex 1523 of 12");
    let e = format!("{:#}", package_changed_hint(cause(), &p, &opened));
    assert!(e.contains("p.motu") && !e.contains("changed"), "{e}");
    // Replaced by a rename, as an import does.
    let q = dir.path().join("q.motu");
    std::fs::write(&q, b"a second, longer package").unwrap();
    std::fs::rename(&q, &p).unwrap();
    let e = format!("{:#}", package_changed_hint(cause(), &p, &opened));
    assert!(
        e.contains("p.motu")
            && e.contains("changed while it was read")
            && e.contains("vertex 1523"),
        "{e}"
    );
}

#[test]
fn first_pass_misses_are_named_only_when_present() {
    assert_eq!(first_pass_misses(0, 0, 0), "");
    assert_eq!(
        first_pass_misses(284, 24, 8),
        " (first pass missed 316 structures: 284 the probe asked for, 24 no probe ray met, 8 \
             passed unseen and evicted)"
    );
    assert_eq!(
        first_pass_misses(0, 0, 3),
        " (first pass missed 3 structures: 3 passed unseen and evicted)"
    );
}

#[test]
fn a_working_set_over_its_room_is_called_out() {
    let mib = 1u64 << 20;
    let over = working_set_note(24 * mib, 13 * mib);
    assert!(over.contains("OVER its room"), "{over}");
    assert!(
        over.contains("24.0 MiB") && over.contains("13.0 MiB"),
        "{over}"
    );
    let fits = working_set_note(7 * mib, 13 * mib);
    assert!(
        fits.starts_with("working set 7.0 MiB in a room of"),
        "{fits}"
    );
}

#[test]
fn eviction_causes_are_named_only_when_present() {
    assert_eq!(evicted_causes(0, 0), "");
    assert_eq!(evicted_causes(3, 0), " (3 for TLAS rebuilds)");
    assert_eq!(evicted_causes(0, 2), " (2 after refused allocations)");
    assert_eq!(
        evicted_causes(3, 2),
        " (3 for TLAS rebuilds, 2 after refused allocations)"
    );
}
