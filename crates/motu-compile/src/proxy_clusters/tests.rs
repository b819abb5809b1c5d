use super::*;
use motu_abi::{BlasRecord, InstanceRecord, TlasRecord, BLAS_AABBS, BLAS_TRIANGLES, NONE_U32};

/// Two TLASes: the first of 300 instances of two triangle BLASes and one AABB BLAS (no
/// clusters for it), the second of 40 instances of the first BLAS.
struct Tables {
    tlases: Vec<TlasRecord>,
    instances: Vec<InstanceRecord>,
    blases: Vec<BlasRecord>,
}

fn tables() -> Tables {
    let blas = |kind, lo: f32, hi: f32| BlasRecord {
        kind,
        item_base: 0,
        item_count: 1,
        level: 1,
        bounds_min: [lo; 3],
        primitive_count: 100,
        bounds_max: [hi; 3],
        _pad: 0,
    };
    let blases = vec![
        blas(BLAS_TRIANGLES, -1.0, 1.0),
        blas(BLAS_TRIANGLES, -0.5, 0.5),
        blas(BLAS_AABBS, -2.0, 2.0),
    ];
    let at = |i: usize, b: u32| {
        let (x, z) = ((i % 20) as f32 * 3.0, (i / 20) as f32 * 3.0);
        InstanceRecord {
            tlas_from_blas: [1.0, 0.0, 0.0, x, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, z],
            blas: b,
            flags: 0,
            element: NONE_U32,
            _pad: 0,
        }
    };
    let mut instances: Vec<InstanceRecord> = (0..300).map(|i| at(i, (i % 3) as u32)).collect();
    instances.extend((0..40).map(|i| at(i, 0)));
    let tlas = |base, count| TlasRecord {
        instance_base: base,
        instance_count: count,
        level: 0,
        element: NONE_U32,
        bounds_min: [-10.0; 3],
        box_list_instances: 0,
        bounds_max: [100.0; 3],
        ..Default::default()
    };
    Tables {
        tlases: vec![tlas(0, 300), tlas(300, 40)],
        instances,
        blases,
    }
}

fn view(t: &Tables) -> HierarchyView<'_> {
    HierarchyView {
        tlases: &t.tlases,
        instances: &t.instances,
        blases: &t.blases,
        ..Default::default()
    }
}

#[test]
fn clusters_cover_each_triangle_instance_once_within_the_cap() {
    let t = tables();
    let v = view(&t);
    let all = all_clusters(&v);
    assert_eq!(all.len(), 2);
    for (tl, list) in all.iter().enumerate() {
        let rec = t.tlases[tl];
        let mut seen: Vec<u32> = list.iter().flat_map(|c| c.members.clone()).collect();
        seen.sort_unstable();
        let want: Vec<u32> = (0..rec.instance_count)
            .filter(|&i| t.instances[(rec.instance_base + i) as usize].blas != 2)
            .collect();
        assert_eq!(seen, want, "TLAS {tl}");
        for c in list {
            assert!(!c.members.is_empty() && c.members.len() <= CLUSTER_INSTANCES);
            for &m in &c.members {
                let inst = &t.instances[(rec.instance_base + m) as usize];
                assert_eq!(inst.blas, c.blas);
                let b = &t.blases[c.blas as usize];
                let x = transformed_box(&inst.tlas_from_blas, b.bounds_min, b.bounds_max);
                assert!((0..3).all(|a| c.bounds[a] <= x[a] && x[3 + a] <= c.bounds[3 + a]));
            }
        }
    }
    // Deterministic: the same view, the same clusters.
    assert_eq!(all, all_clusters(&v));
}

#[test]
fn a_section_round_trips_and_a_changed_tlas_reads_stale() {
    let t = tables();
    let v = view(&t);
    let all = all_clusters(&v);
    let bytes = encode_section(&StoredProxyClusters::new(&v, &all));
    let stored = decode_section(&bytes).expect("decodes");
    assert!(stored.fits(&v));
    let bh = blases_hash(&v);
    for (tl, want) in all.iter().enumerate() {
        assert_eq!(
            stored.tlas_clusters(&v, tl, bh),
            Stored::Valid(want.clone())
        );
    }
    // One instance of the second TLAS moved: that TLAS is stale, the first still valid.
    let mut moved = tables();
    moved.instances[310].tlas_from_blas[3] += 0.5;
    let mv = view(&moved);
    assert!(stored.fits(&mv));
    let bh = blases_hash(&mv);
    assert_eq!(
        stored.tlas_clusters(&mv, 0, bh),
        Stored::Valid(all[0].clone())
    );
    assert_eq!(stored.tlas_clusters(&mv, 1, bh), Stored::Stale);
    // Another BLAS table (bounds): every TLAS stale.
    let mut grown = tables();
    grown.blases[1].bounds_max = [0.75; 3];
    let gv = view(&grown);
    let bh = blases_hash(&gv);
    assert!((0..2).all(|tl| stored.tlas_clusters(&gv, tl, bh) == Stored::Stale));
    // Another shape: does not fit.
    let mut fewer = v;
    fewer.instances = &t.instances[..339];
    assert!(!stored.fits(&fewer));
}

#[test]
fn a_damaged_section_is_refused() {
    let t = tables();
    let v = view(&t);
    let bytes = encode_section(&StoredProxyClusters::new(&v, &all_clusters(&v)));
    assert!(decode_section(&bytes[..bytes.len() - 1]).is_none());
    let mut long = bytes.clone();
    long.extend_from_slice(&[0; 4]);
    assert!(decode_section(&long).is_none());
    let mut magic = bytes.clone();
    magic[13] ^= 1;
    assert!(decode_section(&magic).is_none());
    // A TLAS entry that does not start where the previous ended.
    let mut order = bytes.clone();
    order[16 + 32 + 8] ^= 1;
    assert!(decode_section(&order).is_none());
    // A member count that no longer adds up to the member table.
    let first_cluster = 16 + 32 + 2 * std::mem::size_of::<StoredTlas>();
    let mut count = bytes.clone();
    count[first_cluster + 4] ^= 1;
    assert!(decode_section(&count).is_none());
    assert!(decode_section(&[]).is_none());
}

/// The table made a batch of TLASes at a time is the one made from every TLAS's clusters at
/// once, on more TLASes than a batch holds; its section written piece by piece is
/// [`encode_section`]'s bytes.
#[test]
fn the_table_made_in_batches_is_the_table_of_all_clusters() {
    let mut t = tables();
    let base = t.tlases[0];
    // Many TLASes over overlapping ranges of the same instances.
    t.tlases = (0..700u32)
        .map(|i| TlasRecord {
            instance_base: i % 290,
            instance_count: 10 + i % 50,
            ..base
        })
        .collect();
    let v = view(&t);
    let batched = StoredProxyClusters::of_view(&v);
    assert_eq!(batched, StoredProxyClusters::new(&v, &all_clusters(&v)));
    assert_eq!(batched.tlases.len(), 700);
    let mut pieces = Vec::new();
    write_section(&batched, |p| {
        pieces.extend_from_slice(p);
        Ok::<(), ()>(())
    })
    .unwrap();
    assert_eq!(pieces, encode_section(&batched));
    assert_eq!(pieces.len(), section_bytes(&batched));
    assert_eq!(decode_section(&pieces).unwrap(), batched);
}

/// [`tlas_clusters`] as it was made before the flat table (session 40): per BLAS its own
/// growing lists, each cut by the SAH and copied out cluster by cluster. The reference the
/// flat form must equal.
fn reference_tlas_clusters(view: &HierarchyView<'_>, t: usize) -> Vec<Cluster> {
    let rec = &view.tlases[t];
    type Bounds = ([f32; 3], [f32; 3]);
    let mut by_blas: std::collections::BTreeMap<u32, (Vec<u32>, Vec<Bounds>)> = Default::default();
    for (local, inst) in view.instances[rec.instance_range()].iter().enumerate() {
        let br = &view.blases[inst.blas as usize];
        if !has_boxes(br) {
            continue;
        }
        let x = transformed_box(&inst.tlas_from_blas, br.bounds_min, br.bounds_max);
        let entry = by_blas.entry(inst.blas).or_default();
        entry.0.push(local as u32);
        entry.1.push(([x[0], x[1], x[2]], [x[3], x[4], x[5]]));
    }
    let mut out = Vec::new();
    let mut ranges = Vec::new();
    for (blas, (mut items, mut bounds)) in by_blas {
        ranges.clear();
        crate::sah_partition(&mut items, &mut bounds, CLUSTER_INSTANCES, &mut ranges);
        for &(begin, end) in &ranges {
            let mut b = EMPTY;
            for (lo, hi) in &bounds[begin..end] {
                for a in 0..3 {
                    b[a] = b[a].min(lo[a]);
                    b[3 + a] = b[3 + a].max(hi[a]);
                }
            }
            out.push(Cluster {
                blas,
                bounds: padded(b),
                members: items[begin..end].to_vec(),
            });
        }
    }
    out
}

/// The clusters made in one flat items array per TLAS are the ones made per BLAS in their own
/// lists: on the small tables, and on a TLAS large enough for the SAH's parallel path
/// (three BLASes interleaved, one without boxes); the batched table (batches bounded by
/// instances) is the table of all clusters.
#[test]
fn flat_clusters_are_the_per_blas_clusters() {
    let t = tables();
    let v = view(&t);
    for tl in 0..v.tlases.len() {
        assert_eq!(tlas_clusters(&v, tl), reference_tlas_clusters(&v, tl));
    }
    let mut big = tables();
    let n = 3 * crate::split::PARALLEL_ITEMS as u32 + 77;
    let proto = big.instances[0];
    big.instances = (0..n)
        .map(|i| {
            let mut r = proto;
            let (x, z) = ((i % 700) as f32 * 2.5, (i / 700) as f32 * 2.5);
            r.tlas_from_blas[3] = x;
            r.tlas_from_blas[11] = z + (i % 7) as f32 * 0.25;
            r.blas = [0, 1, 0, 2, 1][(i % 5) as usize];
            r
        })
        .collect();
    let base = big.tlases[0];
    big.tlases = vec![
        TlasRecord {
            instance_base: 0,
            instance_count: n,
            ..base
        },
        TlasRecord {
            instance_base: 5,
            instance_count: 1000,
            ..base
        },
    ];
    let v = view(&big);
    for tl in 0..2 {
        let flat = tlas_clusters(&v, tl);
        // Every instance of the two BLASes with boxes in a cluster of at most 16.
        assert!(flat.len() * CLUSTER_INSTANCES >= v.tlases[tl].instance_count as usize * 3 / 5);
        assert_eq!(flat, reference_tlas_clusters(&v, tl));
    }
    assert_eq!(
        StoredProxyClusters::of_view(&v),
        StoredProxyClusters::new(&v, &all_clusters(&v))
    );
}
