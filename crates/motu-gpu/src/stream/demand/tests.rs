use super::Demand;

#[test]
fn needed_structures_are_those_some_ray_requested() {
    let d = Demand {
        blases: vec![(5, 3), (2, 1), (9, 0)],
        later: vec![(4, 0)],
    };
    assert_eq!(d.needed_ids(), vec![5, 2]);
}

#[test]
fn merged_demand_puts_the_probe_first_and_keeps_each_structure_once() {
    let mut guard = Demand {
        blases: vec![(7, 0), (3, 0)],
        later: vec![(9, 0), (4, 0)],
    };
    let probe = Demand {
        blases: vec![(3, 5), (1, 2)],
        later: vec![(7, 0), (2, 0)],
    };
    guard.merge_first(probe);
    assert_eq!(guard.blases, vec![(3, 5), (1, 2), (7, 0)]);
    // 7 is already needed ahead: it is not built twice.
    assert_eq!(guard.later, vec![(2, 0), (9, 0), (4, 0)]);
}
