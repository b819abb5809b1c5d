use super::*;

fn key(f: impl FnOnce(&mut CacheKeyBuilder)) -> CacheKey {
    let mut b = CacheKeyBuilder::new("test");
    f(&mut b);
    b.finish()
}

#[test]
fn hex_round_trips_and_rejects_bad_strings() {
    let k = key(|b| {
        b.bytes(b"mesh").u64(7);
    });
    let hex = k.to_hex();
    assert_eq!(hex.len(), 64);
    assert_eq!(CacheKey::from_hex(&hex), Ok(k));
    assert_eq!(CacheKey::from_hex(&hex.to_uppercase()), Ok(k));
    assert_eq!(CacheKey::from_hex("abc"), Err(KeyParseError::Length(3)));
    let bad = format!("g{}", &hex[1..]);
    assert_eq!(CacheKey::from_hex(&bad), Err(KeyParseError::Digit('g')));
    assert_eq!(format!("{k}"), hex);
}

#[test]
fn same_fields_same_key_and_framing_separates_fields() {
    let a = key(|b| {
        b.bytes(b"ab").bytes(b"c");
    });
    assert_eq!(
        a,
        key(|b| {
            b.bytes(b"ab").bytes(b"c");
        })
    );
    assert_ne!(
        a,
        key(|b| {
            b.bytes(b"a").bytes(b"bc");
        })
    );
    assert_ne!(
        key(|b| {
            b.u64(1);
        }),
        key(|b| {
            b.bytes(&1u64.to_le_bytes());
        })
    );
    assert_ne!(
        key(|b| {
            b.u32(1);
        }),
        key(|b| {
            b.u64(1);
        })
    );
    assert_ne!(
        key(|b| {
            b.str("x");
        }),
        key(|b| {
            b.bytes(b"x");
        })
    );
    let mut other_domain = CacheKeyBuilder::new("other");
    other_domain.bytes(b"ab").bytes(b"c");
    assert_ne!(a, other_domain.finish());
}

#[test]
fn halves_are_independent_streams() {
    let k = key(|b| {
        b.u64(42);
    });
    assert_ne!(k.0[..16], k.0[16..]);
}

#[test]
fn no_collisions_among_many_small_inputs() {
    let mut seen = std::collections::HashSet::new();
    for i in 0..20_000u64 {
        assert!(seen.insert(key(|b| {
            b.u64(i);
        })));
    }
}
