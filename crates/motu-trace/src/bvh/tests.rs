use super::*;

fn boxes(n: usize) -> Vec<Aabb> {
    // A deterministic scatter of small boxes.
    (0..n)
        .map(|i| {
            let f = i as f32;
            let p = [
                (f * 0.618).fract() * 100.0,
                (f * 0.414).fract() * 50.0,
                (f * 0.732).fract() * 10.0,
            ];
            Aabb::new(p, [p[0] + 0.5, p[1] + 0.3, p[2] + 0.2])
        })
        .collect()
}

/// Every item in exactly one leaf, every child inside its parent.
fn check(bvh: &Bvh, boxes: &[Aabb]) {
    let mut seen = vec![0u32; boxes.len()];
    let mut stack = vec![0usize];
    while let Some(i) = stack.pop() {
        let n = bvh.nodes[i];
        let nb = Aabb::new(n.min, n.max);
        if n.is_leaf() {
            for &item in &bvh.order[n.first as usize..(n.first + n.count) as usize] {
                seen[item as usize] += 1;
                assert!(nb.contains(&boxes[item as usize], 0.0));
            }
        } else {
            for c in [n.first as usize, n.first as usize + 1] {
                let cn = bvh.nodes[c];
                assert!(nb.contains(&Aabb::new(cn.min, cn.max), 0.0));
                stack.push(c);
            }
        }
    }
    assert!(seen.iter().all(|&s| s == 1));
}

#[test]
fn serial_and_parallel_builds_cover_every_item_once() {
    let b = boxes(20_000);
    let par = Bvh::build(
        &b,
        BuildParams {
            parallel_threshold: 256,
            ..Default::default()
        },
    );
    check(&par, &b);
    let ser = Bvh::build(&b, BuildParams::default().serial());
    check(&ser, &b);
    assert!(par.depth() < 64, "depth {}", par.depth());
}

#[test]
fn identical_boxes_and_empty_input() {
    let b = vec![Aabb::new([1.0; 3], [2.0; 3]); 100];
    let bvh = Bvh::build(&b, BuildParams::default());
    check(&bvh, &b);
    assert!(Bvh::build(&[], BuildParams::default()).nodes.is_empty());
    let with_empty = [Aabb::EMPTY, Aabb::new([0.0; 3], [1.0; 3])];
    assert_eq!(
        Bvh::build(&with_empty, BuildParams::default()).order,
        vec![1]
    );
}
