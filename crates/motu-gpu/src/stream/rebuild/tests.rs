use super::group_by_need;

#[test]
fn large_rebuilds_go_alone_and_small_ones_together() {
    let budget = 64 * 100;
    // Three pieces over a 64th of the budget, three small TLASes.
    let mut dirty = vec![(10, 4), (250, 1), (1, 6), (300, 0), (5, 5), (200, 2)];
    let mut groups = Vec::new();
    while !dirty.is_empty() {
        let (g, need) = group_by_need(dirty.clone(), budget);
        let listed: u64 = dirty
            .iter()
            .filter(|(_, t)| g.contains(t))
            .map(|p| p.0)
            .sum();
        assert_eq!(need, listed);
        dirty.retain(|(_, t)| !g.contains(t));
        groups.push(g);
    }
    assert_eq!(groups, vec![vec![0], vec![1], vec![2], vec![4, 5, 6]]);
    // One TLAS over the cap still gets a group of its own.
    assert_eq!(group_by_need(vec![(9000, 3)], budget), (vec![3], 9000));
    // Equal needs: by index; two that fit a 64th together share a group.
    assert_eq!(
        group_by_need(vec![(40, 2), (40, 1)], budget),
        (vec![1, 2], 80)
    );
    assert_eq!(group_by_need(vec![(60, 2), (60, 1)], budget), (vec![1], 60));
    assert!(group_by_need(Vec::new(), budget).0.is_empty());
}
