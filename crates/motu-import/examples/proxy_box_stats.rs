//! The stored proxy boxes of packages, summed: per package the section's version, its BLASes
//! and boxes, and the total surface area and volume of its leaves and top boxes; for a second
//! package of the same scene, the same sums over the BLASes both hold with equal records
//! (`blas_hash`), and the spread of the per-BLAS leaf-area ratio (second / first). For
//! checking that a change in how the boxes are made leaves them as tight.
//!
//! `cargo run --release -p motu-import --example proxy_box_stats -- A.motu [B.motu]`

use std::collections::HashMap;

use motu_compile::proxy_boxes::{decode_section, fan, Box6, StoredProxyBoxes};

/// `(surface area, volume)` of the non-empty boxes.
fn sums(boxes: &[Box6]) -> (f64, f64) {
    let mut s = (0.0, 0.0);
    for b in boxes.iter().filter(|b| b[0] <= b[3]) {
        let e: [f64; 3] = std::array::from_fn(|a| f64::from(b[3 + a] - b[a]));
        s.0 += 2.0 * (e[0] * e[1] + e[1] * e[2] + e[2] * e[0]);
        s.1 += e[0] * e[1] * e[2];
    }
    s
}

struct Package {
    version: String,
    table: StoredProxyBoxes,
}

fn open(path: &str) -> Result<Package, Box<dyn std::error::Error>> {
    let pkg = motu_pack::ScenePackage::open(std::path::Path::new(path))?;
    let bytes = pkg
        .stored_proxy_boxes()?
        .ok_or("the package has no proxy_boxes section")?;
    let version = String::from_utf8_lossy(&bytes[..16])
        .trim_end_matches('\0')
        .to_string();
    let table = decode_section(bytes).ok_or("the proxy_boxes section does not decode")?;
    Ok(Package { version, table })
}

/// Per BLAS (by hash): leaf (area, volume) and top (area, volume).
fn per_blas(p: &Package) -> HashMap<u64, [(f64, f64); 2]> {
    p.table
        .entries
        .iter()
        .map(|e| {
            let f = e.fan as usize;
            let first = e.first_box as usize;
            let top = &p.table.boxes[first..first + f];
            let leaves = &p.table.boxes[first + f..first + f + f * f];
            (e.hash, [sums(leaves), sums(top)])
        })
        .collect()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.is_empty() || args.len() > 2 {
        return Err("usage: proxy_box_stats A.motu [B.motu]".into());
    }
    let packages: Vec<Package> = args.iter().map(|a| open(a)).collect::<Result<_, _>>()?;
    let tables: Vec<HashMap<u64, [(f64, f64); 2]>> = packages.iter().map(per_blas).collect();
    for (path, (p, t)) in args.iter().zip(packages.iter().zip(&tables)) {
        let total = |i: usize| {
            t.values()
                .fold((0.0, 0.0), |s, v| (s.0 + v[i].0, s.1 + v[i].1))
        };
        let (leaf, top) = (total(0), total(1));
        let fans = p
            .table
            .entries
            .iter()
            .filter(|e| e.fan == fan(u32::MAX))
            .count();
        println!(
            "{path}: {} blases={} boxes={} max_fan_blases={fans} leaf_area={:.6e} \
             leaf_volume={:.6e} top_area={:.6e} top_volume={:.6e}",
            p.version,
            p.table.entries.len(),
            p.table.boxes.len(),
            leaf.0,
            leaf.1,
            top.0,
            top.1
        );
    }
    if let [a, b] = &tables[..] {
        let mut ratios = Vec::new();
        let (mut sa, mut sb) = ([0.0f64; 4], [0.0f64; 4]);
        for (h, va) in a {
            let Some(vb) = b.get(h) else { continue };
            for (s, v) in [(&mut sa, va), (&mut sb, vb)] {
                s[0] += v[0].0;
                s[1] += v[0].1;
                s[2] += v[1].0;
                s[3] += v[1].1;
            }
            if va[0].0 > 0.0 {
                ratios.push(vb[0].0 / va[0].0);
            }
        }
        if ratios.is_empty() {
            return Err("the packages share no BLAS".into());
        }
        ratios.sort_by(f64::total_cmp);
        let q = |f: f64| ratios[((ratios.len() - 1) as f64 * f) as usize];
        println!(
            "common blases={} B/A: leaf_area={:.4} leaf_volume={:.4} top_area={:.4} \
             top_volume={:.4}; per-BLAS leaf-area ratio min={:.4} median={:.4} p90={:.4} \
             max={:.4}",
            ratios.len(),
            sb[0] / sa[0],
            sb[1] / sa[1],
            sb[2] / sa[2],
            sb[3] / sa[3],
            q(0.0),
            q(0.5),
            q(0.9),
            q(1.0)
        );
    }
    Ok(())
}
