//! motu package reader on arbitrary bytes.
//!
//! Every input runs twice: as given (header/trailer/manifest validation), and with all
//! checksums and the trailer's `file_len` recomputed, so mutations reach the manifest,
//! chunk and section decoders instead of stopping at the first checksum mismatch.
#![no_main]
use libfuzzer_sys::fuzz_target;

#[global_allocator]
static GUARD: pbrt_import_fuzz::Guard = pbrt_import_fuzz::Guard((1 << 30) + (64 << 20));
use motu_package::format::{
    checksum, ChunkEntry, ManifestHeader, SectionEntry, Trailer, CHUNK_ENTRY_LEN,
    HEADER_CHECKSUMMED_LEN, HEADER_LEN, MANIFEST_HEADER_LEN, SECTION_ENTRY_LEN,
    TRAILER_CHECKSUMMED_LEN, TRAILER_LEN,
};
use motu_package::{ChunkId, Package, SectionKind};

fn exercise(bytes: &[u8]) {
    let Ok(pkg) = Package::from_bytes(bytes) else {
        return;
    };
    let _ = pkg.verify();
    for i in 0..pkg.chunk_count().min(64) {
        let id = ChunkId(i);
        let _ = pkg.chunk_info(id);
        let _ = pkg.chunk_stored(id);
        if let Ok(c) = pkg.chunk(id) {
            let _ = c.slice_as::<u32>(0, c.len() as u64);
            let _ = c.slice_as::<[f32; 3]>(4, 12);
        }
        let mut dst = vec![0u8; 1 << 16];
        let _ = pkg.read_chunk_into(id, &mut dst);
    }
    let _ = pkg.chunk(ChunkId(u32::MAX));
    let kinds: Vec<SectionKind> = pkg.sections().iter().map(|s| s.kind).collect();
    for kind in kinds {
        let _ = pkg.section_bytes(kind);
        let _ = pkg.section_as::<u32>(kind);
        let _ = pkg.section_as::<[u8; 48]>(kind);
    }
}

fn put<T: bytemuck::Pod>(bytes: &mut [u8], at: usize, value: &T) {
    bytes[at..at + size_of::<T>()].copy_from_slice(bytemuck::bytes_of(value));
}

fn get<T: bytemuck::Pod>(bytes: &[u8], at: usize) -> Option<T> {
    bytes
        .get(at..at.checked_add(size_of::<T>())?)
        .map(bytemuck::pod_read_unaligned)
}

/// Recompute every checksum the reader checks, where the ranges are in bounds.
fn fix_checksums(bytes: &mut [u8]) {
    let len = bytes.len();
    if (len as u64) < HEADER_LEN + TRAILER_LEN {
        return;
    }
    let header_sum = checksum(&bytes[..HEADER_CHECKSUMMED_LEN]);
    put(bytes, HEADER_CHECKSUMMED_LEN, &header_sum);
    let tpos = len - TRAILER_LEN as usize;
    let Some(mut trailer) = get::<Trailer>(bytes, tpos) else {
        return;
    };
    trailer.file_len = len as u64;
    let moff = trailer.manifest_offset as usize;
    let mlen = trailer.manifest_len as usize;
    if let Some(end) = moff.checked_add(mlen).filter(|&e| e <= len) {
        if let Some(mh) = get::<ManifestHeader>(bytes, moff) {
            let chunks = (mh.chunk_count as usize).min(4096);
            let sections = (mh.section_count as usize).min(4096);
            let first = moff + MANIFEST_HEADER_LEN as usize;
            for i in 0..chunks {
                let at = first + i * CHUNK_ENTRY_LEN as usize;
                let Some(mut e) = get::<ChunkEntry>(bytes, at) else {
                    break;
                };
                let range =
                    (e.offset as usize)..(e.offset as usize).saturating_add(e.stored_len as usize);
                if let Some(data) = bytes.get(range) {
                    e.checksum = checksum(data);
                    put(bytes, at, &e);
                }
            }
            let first = first + chunks * CHUNK_ENTRY_LEN as usize;
            for i in 0..sections {
                let at = first + i * SECTION_ENTRY_LEN as usize;
                let Some(mut e) = get::<SectionEntry>(bytes, at) else {
                    break;
                };
                let range = (e.offset as usize)..(e.offset as usize).saturating_add(e.len as usize);
                if let Some(data) = bytes.get(range) {
                    e.checksum = checksum(data);
                    put(bytes, at, &e);
                }
            }
        }
        trailer.manifest_checksum = checksum(&bytes[moff..end]);
    }
    trailer.checksum = checksum(&bytemuck::bytes_of(&trailer)[..TRAILER_CHECKSUMMED_LEN]);
    put(bytes, tpos, &trailer);
}

fuzz_target!(|data: &[u8]| {
    exercise(data);
    let mut fixed = data.to_vec();
    fix_checksums(&mut fixed);
    exercise(&fixed);
});
