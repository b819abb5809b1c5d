use super::*;
use proptest::prelude::*;

#[test]
fn evicts_least_recent_first_and_get_refreshes() {
    let mut lru = ByteLru::new(10);
    for k in 0..5u32 {
        assert!(lru.insert(k, (), 2).unwrap().is_empty());
    }
    assert_eq!(lru.bytes(), 10);
    lru.get(&0);
    let evicted = lru.insert(9, (), 3).unwrap();
    let keys: Vec<u32> = evicted.iter().map(|e| e.key).collect();
    assert_eq!(keys, [1, 2], "0 was refreshed, so 1 and 2 go");
    assert_eq!(lru.keys_lru_first(), [3, 4, 0, 9]);
    assert_eq!(lru.bytes(), 9);
}

#[test]
fn too_heavy_is_refused_and_replacing_keeps_the_count() {
    let mut lru = ByteLru::new(10);
    lru.insert(1u32, "a", 4).unwrap();
    assert_eq!(lru.insert(2, "b", 11).err(), Some("b"));
    assert_eq!(lru.len(), 1);
    assert!(lru.insert(1, "c", 6).unwrap().is_empty());
    assert_eq!((lru.len(), lru.bytes()), (1, 6));
    assert_eq!(lru.peek(&1), Some(&"c"));
    let evicted = lru.set_capacity(5);
    assert_eq!(evicted.len(), 1);
    assert_eq!((lru.len(), lru.bytes()), (0, 0));
}

#[derive(Debug, Clone)]
enum Op {
    Insert(u8, u64),
    Get(u8),
    Remove(u8),
    Capacity(u64),
}

fn op() -> impl Strategy<Value = Op> {
    prop_oneof![
        4 => (0u8..16, 0u64..40).prop_map(|(k, w)| Op::Insert(k, w)),
        3 => (0u8..16).prop_map(Op::Get),
        1 => (0u8..16).prop_map(Op::Remove),
        1 => (0u64..120).prop_map(Op::Capacity),
    ]
}

proptest! {
    /// The map against a model (a Vec, least recent first): same contents and order,
    /// never over the bound, the entry just inserted or read always kept, and evictions
    /// take exactly the least recent entries.
    #[test]
    fn matches_a_model_and_never_exceeds_the_bound(
        capacity in 0u64..100,
        ops in proptest::collection::vec(op(), 1..200),
    ) {
        let mut lru = ByteLru::new(capacity);
        let mut model: Vec<(u8, u64)> = Vec::new();
        let mut cap = capacity;
        for op in ops {
            match op {
                Op::Insert(k, w) => {
                    let r = lru.insert(k, w, w);
                    if w > cap {
                        prop_assert!(r.is_err());
                    } else {
                        model.retain(|e| e.0 != k);
                        let mut expected = Vec::new();
                        while model.iter().map(|e| e.1).sum::<u64>() + w > cap {
                            expected.push(model.remove(0).0);
                        }
                        model.push((k, w));
                        let got: Vec<u8> = r.unwrap().iter().map(|e| e.key).collect();
                        prop_assert_eq!(got, expected);
                        prop_assert!(lru.contains(&k), "just inserted must be kept");
                    }
                }
                Op::Get(k) => {
                    let got = lru.get(&k).copied();
                    let pos = model.iter().position(|e| e.0 == k);
                    prop_assert_eq!(got, pos.map(|p| model[p].1));
                    if let Some(p) = pos {
                        let e = model.remove(p);
                        model.push(e);
                    }
                }
                Op::Remove(k) => {
                    let got = lru.remove(&k).map(|r| r.1);
                    let pos = model.iter().position(|e| e.0 == k);
                    prop_assert_eq!(got, pos.map(|p| model.remove(p).1));
                }
                Op::Capacity(c) => {
                    cap = c;
                    let got: Vec<u8> = lru.set_capacity(c).iter().map(|e| e.key).collect();
                    let mut expected = Vec::new();
                    while model.iter().map(|e| e.1).sum::<u64>() > cap {
                        expected.push(model.remove(0).0);
                    }
                    prop_assert_eq!(got, expected);
                }
            }
            prop_assert!(lru.bytes() <= lru.capacity());
            prop_assert_eq!(lru.bytes(), model.iter().map(|e| e.1).sum::<u64>());
            prop_assert_eq!(lru.keys_lru_first(), model.iter().map(|e| e.0).collect::<Vec<_>>());
        }
    }
}
