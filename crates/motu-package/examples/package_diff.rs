//! Compares two packages part by part: every chunk's stored bytes (and offset), then every
//! section's bytes, by name, leaving out the sections named on the command line (`meta`, whose
//! JSON holds the import's timings, by default). A whole-file `cmp` cannot tell a changed
//! section from later bytes moved by a longer meta, nor equal chunks written in another order.
//! Exits 1 when anything compared differs.
//!
//! `cargo run --release -p motu-package --example package_diff -- A.motu B.motu [SKIP,..]`

fn main() -> Result<(), motu_package::PackageError> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(a), Some(b)) = (args.first(), args.get(1)) else {
        eprintln!("usage: package_diff A.motu B.motu [SKIP,..] (default skip: meta)");
        std::process::exit(2);
    };
    let skip: Vec<&str> = args.get(2).map_or(vec!["meta"], |s| s.split(',').collect());
    let (pa, pb) = (
        motu_package::Package::open(a)?,
        motu_package::Package::open(b)?,
    );
    let mut differ = 0usize;
    let (ca, cb) = (pa.chunks(), pb.chunks());
    if ca.len() != cb.len() {
        println!("chunk count: {} vs {}", ca.len(), cb.len());
        differ += 1;
    }
    // Chunks written by several threads may lie in another order in the file: their bytes,
    // tag and group are compared, and where they lie only counted.
    let mut moved = std::collections::BTreeMap::<u32, usize>::new();
    for (x, y) in ca.iter().zip(cb) {
        if x.offset != y.offset {
            *moved.entry(x.group).or_default() += 1;
        }
        let same = pa.chunk_stored(x.id)? == pb.chunk_stored(y.id)?
            && (x.raw_len, x.tag, x.group) == (y.raw_len, y.tag, y.group);
        if !same {
            println!(
                "chunk {:?} differs ({} vs {} bytes stored)",
                x.id, x.stored_len, y.stored_len
            );
            differ += 1;
        }
    }
    println!(
        "{} chunks lie at other offsets (by chunk group: {moved:?})",
        moved.values().sum::<usize>()
    );
    let mut compared = 0usize;
    for s in pa.sections() {
        if skip.contains(&s.name.as_str()) {
            println!("section {} ({} vs ?) skipped", s.name, s.len_bytes);
            continue;
        }
        let Some(t) = pb.sections().iter().find(|t| t.name == s.name) else {
            println!("section {} only in {a}", s.name);
            differ += 1;
            continue;
        };
        compared += 1;
        if pa.section_bytes(s.kind)? != pb.section_bytes(t.kind)? {
            println!(
                "section {} differs ({} vs {} bytes)",
                s.name, s.len_bytes, t.len_bytes
            );
            differ += 1;
        }
    }
    for t in pb.sections() {
        if !skip.contains(&t.name.as_str()) && !pa.sections().iter().any(|s| s.name == t.name) {
            println!("section {} only in {b}", t.name);
            differ += 1;
        }
    }
    println!(
        "{} chunks and {compared} sections compared: {}",
        ca.len().min(cb.len()),
        if differ == 0 {
            "equal".to_string()
        } else {
            format!("{differ} differ")
        }
    );
    std::process::exit(i32::from(differ > 0));
}
