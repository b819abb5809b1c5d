use super::{Demand, Request};

/// A demand of `needed` and `later` (BLAS, requests) pairs, in order.
fn demand(needed: &[(u32, u32)], later: &[u32]) -> Demand {
    let mut d = Demand::default();
    for &(b, n) in needed {
        d.need(b, n);
    }
    for &b in later {
        d.open(b);
    }
    d
}

fn pairs(list: &[Request]) -> Vec<(u32, u32)> {
    list.iter().map(|r| (r.blas, r.requests)).collect()
}

#[test]
fn needed_structures_are_those_some_ray_requested() {
    let d = demand(&[(5, 3), (2, 1), (9, 0)], &[4]);
    assert_eq!(d.needed_ids(), vec![5, 2]);
    assert_eq!(d.len(), 4);
}

#[test]
fn merged_demand_puts_the_probe_first_and_keeps_each_structure_once() {
    let mut guard = demand(&[(7, 0), (3, 0)], &[9, 4]);
    let probe = demand(&[(3, 5), (1, 2)], &[7, 2]);
    guard.merge_first(probe);
    assert_eq!(pairs(guard.needed()), vec![(3, 5), (1, 2), (7, 0)]);
    // 7 is already needed ahead: it is not built twice.
    assert_eq!(pairs(guard.later()), vec![(2, 0), (9, 0), (4, 0)]);
}

#[test]
fn sorted_demand_puts_the_most_requested_first_ties_by_id() {
    let mut d = demand(&[(4, 1), (8, 3), (2, 1)], &[6, 1]);
    d.sort();
    assert_eq!(pairs(d.needed()), vec![(8, 3), (2, 1), (4, 1)]);
    assert_eq!(pairs(d.later()), vec![(1, 0), (6, 0)]);
}
