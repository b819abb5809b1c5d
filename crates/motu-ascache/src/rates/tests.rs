use super::*;

const DEVICE: &str = "lavapipe|00010005:00000000|llvmpipe|Mesa 24|0";

fn some_rates() -> DeviceRates {
    DeviceRates {
        build: Some(Rate {
            batches: 12,
            per_blas_ms: 0.125,
            gb_per_s: 10.5,
        }),
        restore: Some(Rate {
            batches: 3,
            per_blas_ms: 0.0,
            gb_per_s: f64::INFINITY,
        }),
        disk_read: None,
        store: Some(Rate {
            batches: 4,
            per_blas_ms: 0.01,
            gb_per_s: 2.4,
        }),
    }
}

#[test]
fn rates_round_trip_through_the_directory() {
    let dir = tempfile::tempdir().unwrap();
    assert!(matches!(
        load_rates(dir.path(), DEVICE),
        Err(RatesError::Missing)
    ));
    save_rates(dir.path(), DEVICE, &some_rates()).unwrap();
    assert_eq!(load_rates(dir.path(), DEVICE).unwrap(), some_rates());
    // Rewritten in place (rename over the name), no temp file left beside it.
    let mut newer = some_rates();
    newer.disk_read = newer.build;
    save_rates(dir.path(), DEVICE, &newer).unwrap();
    assert_eq!(load_rates(dir.path(), DEVICE).unwrap(), newer);
    let names: Vec<_> = fs::read_dir(dir.path().join(RATES_DIR))
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names.len(), 1, "{names:?}");
    // Another device has a file of its own.
    assert!(matches!(
        load_rates(dir.path(), "another device"),
        Err(RatesError::Missing)
    ));
}

#[test]
fn a_changed_byte_is_corrupt() {
    let text = encode_rates(DEVICE, &some_rates());
    // Any digit changed is caught by the checksum, even where it still parses.
    let at = text.find("10.5").unwrap();
    let mut bad = text.clone().into_bytes();
    bad[at] = b'9';
    let bad = String::from_utf8(bad).unwrap();
    assert!(matches!(
        decode_rates(&bad, DEVICE),
        Err(RatesError::Corrupt("checksum mismatch"))
    ));
    // Cut short, empty, or not this format.
    let cut = &text[..text.len() / 2];
    assert!(matches!(
        decode_rates(cut, DEVICE),
        Err(RatesError::Corrupt(_))
    ));
    assert!(matches!(
        decode_rates("", DEVICE),
        Err(RatesError::Corrupt(_))
    ));
    let other = text.replace(FIRST_LINE, "motu device rates v0");
    assert!(matches!(
        decode_rates(&other, DEVICE),
        Err(RatesError::Corrupt(_))
    ));
}

#[test]
fn a_file_of_another_device_is_foreign() {
    let dir = tempfile::tempdir().unwrap();
    save_rates(dir.path(), "device A", &some_rates()).unwrap();
    // Copied over device B's name: its identity line says whose it is.
    fs::copy(
        rates_path(dir.path(), "device A"),
        rates_path(dir.path(), "device B"),
    )
    .unwrap();
    match load_rates(dir.path(), "device B") {
        Err(e @ RatesError::Foreign(_)) => assert_eq!(e.name(), "foreign"),
        other => panic!("{other:?}"),
    }
    assert_eq!(load_rates(dir.path(), "device A").unwrap(), some_rates());
}

#[test]
fn malformed_rates_are_corrupt_even_with_a_good_checksum() {
    // A writer's bug rather than a flipped byte: the checksum matches its text.
    let seal = |body: &str| format!("{body}checksum {:016x}\n", xxh3_64(body.as_bytes()));
    let head = format!("{FIRST_LINE}\ndevice {DEVICE}\n");
    for line in [
        "build 1 0.1\n",
        "build 1 0.1 -2\n",
        "build 1 NaN 2\n",
        "build 1 0.1 2 extra\n",
        "warp 1 0.1 2\n",
    ] {
        let text = seal(&(head.clone() + line));
        assert!(
            matches!(decode_rates(&text, DEVICE), Err(RatesError::Corrupt(_))),
            "{line:?}"
        );
    }
    let text = seal(&(head + "build 1 0.1 inf\n"));
    assert_eq!(
        decode_rates(&text, DEVICE).unwrap().build.unwrap().gb_per_s,
        f64::INFINITY
    );
}

#[test]
fn hand_written_rates_parse_as_the_file_keeps_them() {
    let r = |per_blas_ms, gb_per_s| {
        Some(Rate {
            batches: 0,
            per_blas_ms,
            gb_per_s,
        })
    };
    assert_eq!(
        parse_rates("build=0.5, restore=4+0.125,disk_read=inf+2,store=2.4").unwrap(),
        DeviceRates {
            build: r(0.0, 0.5),
            restore: r(0.125, 4.0),
            disk_read: r(2.0, f64::INFINITY),
            store: r(0.0, 2.4),
        }
    );
    // What is not named stays unknown.
    assert_eq!(
        parse_rates("restore=1").unwrap(),
        DeviceRates {
            restore: r(0.0, 1.0),
            ..DeviceRates::default()
        }
    );
    // A parsed set survives the file's round trip (a test may forge a file from it).
    let forged = parse_rates("build=0.5,restore=4+0.125,disk_read=inf").unwrap();
    assert_eq!(
        decode_rates(&encode_rates(DEVICE, &forged), DEVICE).unwrap(),
        forged
    );
}

#[test]
fn malformed_hand_written_rates_are_refused_by_name() {
    use RatesSpecError::*;
    for (spec, want) in [
        ("", Malformed(String::new())),
        ("build", Malformed("build".into())),
        ("build=1,", Malformed(String::new())),
        ("bulid=1", UnknownOperation("bulid".into())),
        ("build=0", BadNumber("build=0".into())),
        ("build=-1", BadNumber("build=-1".into())),
        ("build=nan", BadNumber("build=nan".into())),
        ("build=1+-2", BadNumber("build=1+-2".into())),
        ("build=1+inf", BadNumber("build=1+inf".into())),
        ("build=fast", BadNumber("build=fast".into())),
        ("build=1,build=2", Twice("build".into())),
    ] {
        assert_eq!(parse_rates(spec), Err(want), "{spec:?}");
    }
}
