use super::*;

fn table(items: &[(u32, u64, u64)]) -> Residency {
    let mut residency = Residency::new();
    for &(id, bytes, frame) in items {
        residency.insert(ItemId(id), bytes, frame).unwrap();
    }
    residency
}

#[test]
fn victims_are_least_recently_visible() {
    let mut residency = table(&[(1, 100, 5), (2, 100, 1), (3, 100, 3), (4, 100, 0)]);
    assert_eq!(
        residency.choose_victims(150).unwrap(),
        vec![ItemId(4), ItemId(2)]
    );
    assert_eq!(residency.choose_victims(100).unwrap(), vec![ItemId(4)]);
    assert_eq!(residency.choose_victims(0).unwrap(), vec![]);
    // item 4 seen again: now 2 is the oldest.
    assert!(residency.mark_visible(ItemId(4), 6));
    assert_eq!(residency.choose_victims(1).unwrap(), vec![ItemId(2)]);
    // an older frame does not make it older again.
    assert!(residency.mark_visible(ItemId(4), 2));
    assert_eq!(residency.last_visible_frame(ItemId(4)), Some(6));
    assert!(!residency.mark_visible(ItemId(9), 7));
}

#[test]
fn pinned_items_are_never_victims() {
    let mut residency = table(&[(1, 100, 0), (2, 50, 1), (3, 70, 2)]);
    assert!(residency.pin(ItemId(1)));
    assert!(residency.pin(ItemId(1)));
    assert_eq!(residency.pinned_bytes(), 100);
    assert_eq!(
        residency.choose_victims(60).unwrap(),
        vec![ItemId(2), ItemId(3)]
    );
    let err = residency.choose_victims(121).unwrap_err();
    assert_eq!(
        err,
        NotEnough {
            bytes_needed: 121,
            evictable_bytes: 120,
            pinned_bytes: 100,
            resident_bytes: 220
        }
    );
    let message = err.to_string();
    for number in ["121 bytes", "220 bytes", "100 bytes", "120 bytes"] {
        assert!(message.contains(number), "{message}");
    }
    // visible while pinned: the new frame counts once unpinned.
    assert!(residency.mark_visible(ItemId(1), 9));
    residency.unpin_all();
    assert_eq!(residency.pinned_bytes(), 0);
    assert_eq!(
        residency.choose_victims(220).unwrap(),
        vec![ItemId(2), ItemId(3), ItemId(1)]
    );
}

#[test]
fn caller_pinned_set_is_respected() {
    let mut residency = table(&[(1, 100, 0), (2, 50, 1), (3, 70, 2), (4, 10, 3)]);
    residency.pin(ItemId(4));
    let needed_now = |id: ItemId| id == ItemId(2);
    assert_eq!(
        residency.choose_victims_excluding(150, needed_now).unwrap(),
        vec![ItemId(1), ItemId(3)]
    );
    assert_eq!(
        residency.choose_victims_excluding(171, needed_now),
        Err(NotEnough {
            bytes_needed: 171,
            evictable_bytes: 170,
            pinned_bytes: 60,
            resident_bytes: 230
        })
    );
    assert_eq!(
        residency.choose_victims_excluding(0, needed_now).unwrap(),
        vec![]
    );
}

#[test]
fn evict_removes_and_accounts() {
    let mut residency = table(&[(1, 10, 0), (2, 20, 1), (3, 30, 2)]);
    residency.pin(ItemId(3));
    assert_eq!(residency.remove(ItemId(3)), Some(30));
    assert_eq!(residency.pinned_bytes(), 0);
    residency.unpin_all();
    assert_eq!(
        residency.evict(15).unwrap(),
        vec![(ItemId(1), 10), (ItemId(2), 20)]
    );
    assert!(residency.is_empty());
    assert_eq!(residency.resident_bytes(), 0);
    assert_eq!(
        residency
            .insert(ItemId(5), 1, 0)
            .and(residency.insert(ItemId(5), 1, 0)),
        Err(ResidencyError::AlreadyResident(ItemId(5)))
    );
    // re-inserting a removed-while-pinned item works and is not pinned.
    residency.insert(ItemId(3), 30, 4).unwrap();
    assert!(!residency.is_pinned(ItemId(3)));
}
