use super::*;

#[test]
fn a_blob_round_trips_and_refuses_cut_long_or_foreign_bytes() {
    let mut w = BlobWriter::new(b"MAGIC", 0);
    w.u32(7).u64(1 << 40).pods(&[1.5f32, -2.0]);
    let blob = w.finish();
    let read = |b: &[u8]| -> Option<(u32, u64, Vec<f32>)> {
        let mut r = BlobReader::new(b, b"MAGIC")?;
        let v = (r.u32()?, r.u64()?, r.pods::<f32>(2)?);
        r.finish()?;
        Some(v)
    };
    assert_eq!(read(&blob), Some((7, 1 << 40, vec![1.5, -2.0])));
    assert_eq!(read(&blob[..blob.len() - 1]), None);
    let mut long = blob.clone();
    long.push(0);
    assert_eq!(read(&long), None);
    let mut other = blob.clone();
    other[0] ^= 1;
    assert_eq!(read(&other), None);
    let mut r = BlobReader::new(&blob, b"MAGIC").unwrap();
    assert_eq!(r.pods::<u64>(usize::MAX), None);
}
