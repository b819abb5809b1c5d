use super::*;

fn image() -> Aov {
    let mut a = Aov::new(8, 6);
    for (i, r) in a.records.iter_mut().enumerate() {
        if i % 5 != 0 {
            *r = AovRecord {
                mesh: (i % 3) as u32,
                primitive: i as u32,
                t: 10.0 + i as f32,
                lod: 0,
                _pad: 0,
                traces: 1,
            };
        }
    }
    a
}

#[test]
fn detects_one_changed_pixel() {
    let a = image();
    let same = compare(&a, &a, DEFAULT_REL_EPS).unwrap();
    assert_eq!((same.mismatched, same.bbox), (0, None));
    let mut b = a.clone();
    b.records[3 * 8 + 5].primitive += 1;
    let r = compare(&a, &b, DEFAULT_REL_EPS).unwrap();
    assert_eq!(r.mismatched, 1);
    assert_eq!(r.total, 48);
    assert_eq!(r.bbox, Some([5, 3, 5, 3]));
    assert_eq!(&r.diff_rgba8[(3 * 8 + 5) * 4..][..4], &[255, 0, 0, 255]);
    assert!((r.fraction - 1.0 / 48.0).abs() < 1e-12);
}

#[test]
fn distance_tolerance_miss_and_size() {
    let a = image();
    let mut b = a.clone();
    b.records[1].t *= 1.0 + 0.5 * DEFAULT_REL_EPS;
    assert_eq!(compare(&a, &b, DEFAULT_REL_EPS).unwrap().mismatched, 0);
    b.records[1].t = a.records[1].t * (1.0 + 3.0 * DEFAULT_REL_EPS);
    b.records[2] = AovRecord::MISS;
    let r = compare(&a, &b, DEFAULT_REL_EPS).unwrap();
    assert_eq!(r.mismatched, 2);
    assert_eq!(r.bbox, Some([1, 0, 2, 0]));
    // LOD and trace counts do not matter.
    let mut c = a.clone();
    c.records[1].lod = 3;
    c.records[1].traces = 9;
    assert_eq!(compare(&a, &c, DEFAULT_REL_EPS).unwrap().mismatched, 0);
    assert!(matches!(
        compare(&a, &Aov::new(6, 8), DEFAULT_REL_EPS),
        Err(CompareError::Size { .. })
    ));
}
