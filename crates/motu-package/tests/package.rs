//! Round trip, corruption, truncation, foreign-file, atomic-write and fixture tests of the
//! package container.

use std::path::{Path, PathBuf};

use motu_package::format::{self, Header, Trailer, HEADER_LEN, TRAILER_LEN};
use motu_package::{
    ChunkId, Codec, Locator, Package, PackageError, PackageWriter, Part, SectionKind, WriterOptions,
};
use proptest::prelude::*;

mod common;
use common::noise;

const NODES: SectionKind = SectionKind(1);
const TRANSFORMS: SectionKind = SectionKind(2);
const NAMES: SectionKind = SectionKind(3);

/// Compressible bytes: a repeating ramp, like quantised vertex data.
fn ramp(len: usize) -> Vec<u8> {
    (0..len).map(|i| (i / 7) as u8).collect()
}

#[repr(C)]
#[derive(Copy, Clone, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
struct Transform {
    world_from_object: [[f32; 4]; 3],
}

/// What the sample package holds, to compare against what is read back.
struct Sample {
    blobs: Vec<(Locator, Vec<u8>)>,
    nodes: Vec<u32>,
    transforms: Vec<Transform>,
}

fn sample_contents() -> (Vec<Vec<u8>>, Vec<u32>, Vec<Transform>) {
    let blobs = vec![
        ramp(3000),
        noise(1, 2500),
        ramp(100),
        noise(2, 7000),
        Vec::new(),
        ramp(6000),
        noise(3, 10),
    ];
    let nodes = (0..300u32).map(|i| i.wrapping_mul(2_654_435_761)).collect();
    let transforms = (0..5)
        .map(|i| Transform {
            world_from_object: [
                [1.0, 0.0, 0.0, i as f32],
                [0.0, 1.0, 0.0, 2.0 * i as f32],
                [0.0, 0.0, 1.0, -(i as f32)],
            ],
        })
        .collect();
    (blobs, nodes, transforms)
}

/// Writes a small package with two streams, raw and (if `zstd`) compressed chunks, padding
/// everywhere, and three sections.
fn write_sample(path: &Path, zstd: bool) -> Sample {
    let options = WriterOptions {
        target_chunk_bytes: 8192,
        zstd_level: zstd.then_some(3),
        direct_io: false,
    };
    let mut writer = PackageWriter::create(path, options).unwrap();
    let a = writer.open_stream(10, 0);
    let b = writer.open_stream(20, 1);
    let (contents, nodes, transforms) = sample_contents();
    let mut blobs = Vec::new();
    for (i, blob) in contents.into_iter().enumerate() {
        let stream = if i % 3 == 2 { b } else { a };
        let align = [1, 4, 16, 256][i % 4];
        let locator = writer.append(stream, &blob, align).unwrap();
        blobs.push((locator, blob));
    }
    writer.add_section_slice(NODES, "nodes", &nodes).unwrap();
    writer
        .add_section_slice(TRANSFORMS, "transforms", &transforms)
        .unwrap();
    writer
        .add_section(NAMES, "strings", 1, b"isBeach\0isCoral\0")
        .unwrap();
    writer.finish().unwrap();
    Sample {
        blobs,
        nodes,
        transforms,
    }
}

fn check_sample(package: &Package, sample: &Sample) {
    for (locator, blob) in &sample.blobs {
        let chunk = package.chunk(locator.chunk).unwrap();
        let start = locator.offset_in_chunk as usize;
        assert_eq!(&chunk[start..start + blob.len()], &blob[..], "{locator:?}");
    }
    assert_eq!(package.section_as::<u32>(NODES).unwrap(), &sample.nodes[..]);
    assert_eq!(
        package.section_as::<Transform>(TRANSFORMS).unwrap(),
        &sample.transforms[..]
    );
    assert_eq!(package.section_bytes(NAMES).unwrap(), b"isBeach\0isCoral\0");
    package.verify().unwrap();
}

fn sample_bytes(zstd: bool) -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sample.motu");
    write_sample(&path, zstd);
    std::fs::read(&path).unwrap()
}

fn is_corrupt_or_version(err: &PackageError) -> bool {
    matches!(
        err,
        PackageError::Corrupt { .. }
            | PackageError::Version { .. }
            | PackageError::UnsupportedFeatures { .. }
    )
}

#[test]
fn sample_round_trips_raw_and_zstd() {
    for zstd in [false, true] {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scene.motu");
        let sample = write_sample(&path, zstd);
        let package = Package::open(&path).unwrap();
        check_sample(&package, &sample);
        let codecs: Vec<Codec> = package.chunks().iter().map(|c| c.codec).collect();
        assert!(codecs.len() >= 3, "{codecs:?}");
        // zstd is used only where it pays: the noise-only chunk stays raw.
        assert_eq!(codecs.contains(&Codec::Zstd), zstd, "{codecs:?}");
        for info in package.chunks() {
            assert_eq!(info.offset % 4096, 0);
            assert!(info.raw_len <= 8192);
            assert!([10, 20].contains(&info.tag));
            assert_eq!(info.group, if info.tag == 10 { 0 } else { 1 });
            let chunk = package.chunk(info.id).unwrap();
            assert_eq!(chunk.len() as u64, info.raw_len);
            assert_eq!(chunk.is_borrowed(), info.codec == Codec::Raw);
            assert_eq!(chunk.as_ptr() as usize % 64, 0, "chunk bytes are aligned");
            let mut staging = vec![0xAAu8; info.raw_len as usize + 3];
            let written = package.read_chunk_into(info.id, &mut staging).unwrap();
            assert_eq!(&staging[..written], &chunk[..]);
            assert_eq!(&staging[written..], [0xAA; 3]);
            if info.raw_len > 0 {
                let short = package.read_chunk_into(info.id, &mut staging[..written - 1]);
                assert!(matches!(short, Err(PackageError::InvalidArgument(_))));
            }
        }
        let report = package.verify().unwrap();
        assert_eq!(report.file_bytes, std::fs::metadata(&path).unwrap().len());
        assert_eq!(
            report.checksummed_bytes + report.padding_bytes,
            report.file_bytes
        );
    }
}

#[test]
fn locators_respect_alignment_and_chunk_target() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("a.motu");
    let mut writer = PackageWriter::create(
        &path,
        WriterOptions {
            target_chunk_bytes: 1000,
            zstd_level: None,
            direct_io: false,
        },
    )
    .unwrap();
    let mut chunks = writer.chunk_writer(0, 0);
    let first = chunks.append(&[1; 10], 1).unwrap();
    let second = chunks.append(&[2; 10], 64).unwrap();
    assert_eq!((first.chunk, first.offset_in_chunk), (ChunkId(0), 0));
    assert_eq!((second.chunk, second.offset_in_chunk), (ChunkId(0), 64));
    // 64 + 10 + 930 > 1000: starts a new chunk.
    let third = chunks.append(&[3; 930], 8).unwrap();
    assert_eq!((third.chunk, third.offset_in_chunk), (ChunkId(1), 0));
    assert_eq!(chunks.seal_chunk().unwrap(), Some(ChunkId(1)));
    assert_eq!(chunks.seal_chunk().unwrap(), None);
    // A blob over the target gets a chunk of its own (one huge mesh), up to MAX_CHUNK_BYTES.
    let big = chunks.append(&[0; 1001], 1).unwrap();
    assert_eq!(
        (big.chunk, big.offset_in_chunk, big.len_bytes),
        (ChunkId(2), 0, 1001)
    );
    let bad_align = chunks.append(&[0; 1], 3).unwrap_err();
    assert!(
        matches!(bad_align, PackageError::InvalidArgument(_)),
        "{bad_align}"
    );
    chunks.close().unwrap();
    writer.finish().unwrap();
    let package = Package::open(&path).unwrap();
    let chunk0 = package.chunk(ChunkId(0)).unwrap();
    assert_eq!(&chunk0[..], [&[1u8; 10][..], &[0; 54], &[2; 10]].concat());
    assert_eq!(&package.chunk(ChunkId(1)).unwrap()[..], &[3u8; 930][..]);
    assert_eq!(package.chunk(ChunkId(2)).unwrap().len(), 1001);
    assert!(matches!(
        package.chunk(ChunkId(3)),
        Err(PackageError::NoSuchChunk {
            id: ChunkId(3),
            count: 3
        })
    ));
}

#[test]
fn writer_rejects_bad_sections_and_options() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("a.motu");
    let options = WriterOptions {
        target_chunk_bytes: 0,
        zstd_level: None,
        direct_io: false,
    };
    assert!(matches!(
        PackageWriter::create(&path, options),
        Err(PackageError::InvalidArgument(_))
    ));
    let mut writer = PackageWriter::create(&path, WriterOptions::default()).unwrap();
    assert!(writer.add_section(NODES, "nodes", 4, &[0; 6]).is_err());
    assert!(writer.add_section(NODES, "nodes", 0, &[]).is_err());
    writer.add_section(NODES, "nodes", 4, &[0; 8]).unwrap();
    assert!(writer.add_section(NODES, "again", 4, &[0; 8]).is_err());
    writer.finish().unwrap();
}

#[test]
fn section_access_checks_type_and_presence() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.motu");
    let sample = write_sample(&path, false);
    let package = Package::open(&path).unwrap();
    let info = package.section_info(NODES).unwrap();
    assert_eq!((info.name.as_str(), info.element_size), ("nodes", 4));
    assert_eq!(info.count, sample.nodes.len() as u64);
    let wrong = package.section_as::<u64>(NODES).unwrap_err();
    assert!(matches!(wrong, PackageError::SectionType { .. }), "{wrong}");
    assert!(wrong.to_string().contains("section nodes"), "{wrong}");
    let missing = package.section_as::<u32>(SectionKind(99)).unwrap_err();
    assert!(matches!(
        missing,
        PackageError::NoSuchSection {
            kind: SectionKind(99)
        }
    ));
    // Sections are 64-byte aligned, so 16-byte aligned types cast without copying.
    let as_vec4: &[[f32; 4]] =
        bytemuck::try_cast_slice(package.section_bytes(TRANSFORMS).unwrap()).unwrap();
    assert_eq!(as_vec4.len(), 15);
}

#[test]
fn empty_package_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("empty.motu");
    let summary = PackageWriter::create(&path, WriterOptions::default())
        .unwrap()
        .finish()
        .unwrap();
    assert_eq!(summary.chunk_count, 0);
    let package = Package::open(&path).unwrap();
    assert_eq!(package.chunk_count(), 0);
    assert!(package.sections().is_empty());
    let report = package.verify().unwrap();
    assert_eq!(report.file_bytes, summary.file_bytes);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    #[test]
    fn random_packages_round_trip(
        blobs in prop::collection::vec(
            (0usize..3, 0usize..3000, 0u32..5, any::<bool>(), any::<u64>()), 0..24),
        sections in prop::collection::vec((1u32..6, 0usize..400, any::<u64>()), 0..5),
        zstd in any::<bool>(),
        target_chunk_bytes in 3000u64..20_000,
    ) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("p.motu");
        let options = WriterOptions { target_chunk_bytes, zstd_level: zstd.then_some(1), direct_io: false };
        let mut writer = PackageWriter::create(&path, options).unwrap();
        let streams: Vec<_> = (0..3).map(|i| writer.open_stream(i, 100 + i)).collect();
        let mut written = Vec::new();
        for (stream, len, align_log2, compressible, seed) in blobs {
            let blob = if compressible { ramp(len) } else { noise(seed, len) };
            let locator = writer.append(streams[stream], &blob, 1 << align_log2).unwrap();
            prop_assert_eq!(locator.offset_in_chunk % (1 << align_log2), 0);
            written.push((stream as u32, locator, blob));
            if seed % 7 == 0 {
                writer.seal_chunk(streams[stream]).unwrap();
            }
        }
        let mut expected_sections = Vec::new();
        for (kind, len, seed) in sections {
            if expected_sections.iter().any(|(k, _)| *k == kind) {
                continue;
            }
            let bytes = noise(seed, len * 8);
            writer.add_section(SectionKind(kind), &format!("s{kind}"), 8, &bytes).unwrap();
            expected_sections.push((kind, bytes));
        }
        writer.finish().unwrap();

        let package = Package::open(&path).unwrap();
        package.verify().unwrap();
        for (stream, locator, blob) in &written {
            let info = package.chunk_info(locator.chunk).unwrap();
            prop_assert_eq!(info.tag, *stream);
            prop_assert_eq!(info.group, 100 + *stream);
            prop_assert!(info.raw_len <= target_chunk_bytes);
            let chunk = package.chunk(locator.chunk).unwrap();
            let start = locator.offset_in_chunk as usize;
            prop_assert_eq!(&chunk[start..start + blob.len()], &blob[..]);
        }
        for (kind, bytes) in &expected_sections {
            let section: &[u64] = package.section_as(SectionKind(*kind)).unwrap();
            prop_assert_eq!(bytemuck::cast_slice::<u64, u8>(section), &bytes[..]);
        }
        prop_assert_eq!(package.sections().len(), expected_sections.len());
    }
}

/// Byte ranges of the sample's fixed parts, read from its trailer.
struct Layout {
    manifest: std::ops::Range<usize>,
    trailer: std::ops::Range<usize>,
}

fn layout(bytes: &[u8]) -> Layout {
    let trailer_start = bytes.len() - TRAILER_LEN as usize;
    let trailer: Trailer = bytemuck::pod_read_unaligned(&bytes[trailer_start..]);
    let start = trailer.manifest_offset as usize;
    Layout {
        manifest: start..start + trailer.manifest_len as usize,
        trailer: trailer_start..bytes.len(),
    }
}

#[test]
fn every_sampled_single_byte_flip_is_detected() {
    for zstd in [false, true] {
        let good = sample_bytes(zstd);
        let layout = layout(&good);
        let package = Package::from_bytes(&good).unwrap();
        let chunks = package.chunks().to_vec();
        let in_fixed_part = |at: usize| {
            at < HEADER_LEN as usize
                || layout.manifest.contains(&at)
                || layout.trailer.contains(&at)
        };
        // Every byte of the fixed parts and of chunk/section boundaries; every 13th elsewhere.
        let near_boundary = |at: usize| {
            chunks.iter().any(|c| {
                let (start, end) = (c.offset as usize, (c.offset + c.stored_len) as usize);
                at.abs_diff(start) < 8 || at.abs_diff(end) < 8
            })
        };
        let mut checked = 0;
        for at in 0..good.len() {
            if !(in_fixed_part(at) || near_boundary(at) || at % 13 == 0) {
                continue;
            }
            for flip in [0x01u8, 0x80, 0xFF] {
                let mut bad = good.clone();
                bad[at] ^= flip;
                let result = Package::from_bytes(&bad);
                if in_fixed_part(at) {
                    let err = result.as_ref().err();
                    assert!(
                        err.is_some_and(is_corrupt_or_version),
                        "open missed byte {at}"
                    );
                }
                let err = result.and_then(|p| p.verify()).err();
                assert!(
                    err.as_ref().is_some_and(is_corrupt_or_version),
                    "verify missed byte {at}"
                );
                checked += 1;
            }
        }
        assert!(checked > 3000, "{checked}");
    }
}

#[test]
fn verify_names_the_damaged_part() {
    let good = sample_bytes(true);
    let package = Package::from_bytes(&good).unwrap();
    let chunk = package.chunk_info(ChunkId(1)).unwrap();
    let nodes = package.section_info(NODES).unwrap().clone();

    let mut bad = good.clone();
    bad[chunk.offset as usize + 5] ^= 0x10;
    let package = Package::from_bytes(&bad).unwrap();
    let err = package.chunk(ChunkId(1)).unwrap_err();
    assert!(
        matches!(
            &err,
            PackageError::Corrupt {
                part: Part::Chunk(ChunkId(1)),
                ..
            }
        ),
        "{err}"
    );
    let err = package.verify().unwrap_err();
    assert_eq!(
        err.to_string(),
        "corrupt package (chunk 1): checksum mismatch"
    );

    let mut bad = good.clone();
    bad[nodes.offset as usize] ^= 0x10;
    let err = Package::from_bytes(&bad).unwrap().verify().unwrap_err();
    assert_eq!(
        err.to_string(),
        "corrupt package (section nodes): checksum mismatch"
    );

    // Padding after the header and after a chunk.
    for at in [
        HEADER_LEN as usize + 100,
        (chunk.offset + chunk.stored_len) as usize + 1,
    ] {
        let mut bad = good.clone();
        bad[at] = 0x42;
        let package = Package::from_bytes(&bad).unwrap();
        let err = package.verify().unwrap_err();
        assert!(
            matches!(
                &err,
                PackageError::Corrupt {
                    part: Part::Padding { .. },
                    ..
                }
            ),
            "{err}"
        );
        assert!(
            err.to_string().contains(&format!("byte {at} is 0x42")),
            "{err}"
        );
    }
}

#[test]
fn truncation_anywhere_is_detected_by_open() {
    let good = sample_bytes(true);
    let len = good.len();
    for cut in (0..len).filter(|&cut| cut < 200 || cut + 200 > len || cut % 97 == 0) {
        let err = Package::from_bytes(&good[..cut]).unwrap_err();
        assert!(
            matches!(err, PackageError::Corrupt { .. }),
            "cut at {cut}: {err}"
        );
    }
    // Appended bytes are detected too.
    let mut longer = good.clone();
    longer.extend_from_slice(&[0; 8]);
    assert!(Package::from_bytes(&longer).is_err());

    // And on a real file through the mmap path.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.motu");
    for cut in [0, 1, 64, 4096, len / 2, len - 48, len - 1] {
        std::fs::write(&path, &good[..cut]).unwrap();
        let err = Package::open(&path).unwrap_err();
        assert!(
            matches!(err, PackageError::Corrupt { .. }),
            "cut at {cut}: {err}"
        );
    }
}

/// The 8-byte signature and IHDR chunk of a 1×1 PNG, padded like a real small image.
fn png_bytes() -> Vec<u8> {
    let mut png = vec![0x89, b'P', b'N', b'G', 0x0D, 0x0A, 0x1A, 0x0A];
    png.extend_from_slice(&[
        0, 0, 0, 13, b'I', b'H', b'D', b'R', 0, 0, 0, 1, 0, 0, 0, 1, 8, 6,
    ]);
    png.extend_from_slice(&noise(9, 5000));
    png.extend_from_slice(&[0, 0, 0, 0, b'I', b'E', b'N', b'D', 0xAE, 0x42, 0x60, 0x82]);
    png
}

#[test]
fn foreign_files_give_clean_errors() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("foreign");
    let cases: Vec<(&str, Vec<u8>)> = vec![
        ("empty", Vec::new()),
        ("tiny", b"hello".to_vec()),
        ("noise", noise(5, 100_000)),
        ("png", png_bytes()),
        ("magic only", [&b"MOTUPKG\0"[..], &noise(6, 9000)].concat()),
    ];
    for (what, bytes) in cases {
        std::fs::write(&path, &bytes).unwrap();
        // A foreign file with our magic but garbage after it gets a version error, which is
        // just as clean.
        let err = Package::open(&path).unwrap_err();
        assert!(is_corrupt_or_version(&err), "{what}: {err}");
        let err = Package::from_bytes(&bytes).unwrap_err();
        assert!(is_corrupt_or_version(&err), "{what}: {err}");
    }
    let err = Package::open(dir.path().join("missing.motu")).unwrap_err();
    assert!(matches!(err, PackageError::Io { .. }), "{err}");
}

/// Rewrites the header with `edit` applied and a valid checksum.
fn with_header(bytes: &[u8], edit: impl FnOnce(&mut Header)) -> Vec<u8> {
    let mut header: Header = bytemuck::pod_read_unaligned(&bytes[..HEADER_LEN as usize]);
    edit(&mut header);
    header.checksum = format::checksum(&bytemuck::bytes_of(&header)[..56]);
    let mut out = bytes.to_vec();
    out[..HEADER_LEN as usize].copy_from_slice(bytemuck::bytes_of(&header));
    out
}

#[test]
fn compatibility_rule_same_major_any_minor() {
    let good = sample_bytes(false);
    let next_major = with_header(&good, |h| h.version_major += 1);
    let err = Package::from_bytes(&next_major).unwrap_err();
    assert!(
        matches!(err, PackageError::Version { found, supported }
            if found.major == 2 && supported.major == 1),
        "{err}"
    );
    // A later minor with optional features and reserved fields in use still reads.
    let next_minor = with_header(&good, |h| {
        h.version_minor += 1;
        h.optional_features = 0b101;
        h.reserved = [7, 7];
    });
    let package = Package::from_bytes(&next_minor).unwrap();
    assert_eq!(package.format_version().minor, 1);
    assert_eq!(package.optional_features(), 0b101);
    package.verify().unwrap();
    let required = with_header(&good, |h| h.required_features = 1 << 40);
    let err = Package::from_bytes(&required).unwrap_err();
    assert!(matches!(err, PackageError::UnsupportedFeatures { bits } if bits == 1 << 40));
}

fn dir_entries(dir: &Path) -> Vec<PathBuf> {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    entries.sort();
    entries
}

#[test]
fn dropped_writer_leaves_no_file_and_keeps_old_target() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.motu");
    {
        let mut writer = PackageWriter::create(&path, WriterOptions::default()).unwrap();
        writer
            .chunk_writer(0, 0)
            .append(&noise(1, 50_000), 16)
            .unwrap();
        let temp = writer.temp_path().unwrap().to_path_buf();
        assert_eq!(
            temp.parent(),
            Some(dir.path()),
            "temp file lies beside the target"
        );
        assert!(temp.exists());
        assert!(!path.exists());
    }
    assert!(
        dir_entries(dir.path()).is_empty(),
        "{:?}",
        dir_entries(dir.path())
    );

    // An existing package stays intact until a new one is finished.
    let sample = write_sample(&path, false);
    let before = std::fs::read(&path).unwrap();
    {
        let mut writer = PackageWriter::create(&path, WriterOptions::default()).unwrap();
        writer.add_section(NODES, "nodes", 1, b"new").unwrap();
    }
    assert_eq!(std::fs::read(&path).unwrap(), before);
    assert_eq!(dir_entries(dir.path()), vec![path.clone()]);
    check_sample(&Package::open(&path).unwrap(), &sample);

    // finish() replaces it atomically and leaves no temp file.
    let mut writer = PackageWriter::create(&path, WriterOptions::default()).unwrap();
    writer.add_section(NODES, "nodes", 1, b"new").unwrap();
    writer.finish().unwrap();
    assert_eq!(dir_entries(dir.path()), vec![path.clone()]);
    assert_eq!(
        Package::open(&path).unwrap().section_bytes(NODES).unwrap(),
        b"new"
    );
}

/// Chunk checksums are checked on first touch only; `verify` always rereads. This pins the
/// documented trade-off: a file modified under an open package is caught by `verify`.
#[cfg(target_os = "linux")]
#[test]
fn chunk_checksum_is_checked_on_first_touch_and_by_verify() {
    use std::io::{Seek, SeekFrom, Write};
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.motu");
    write_sample(&path, false);
    let package = Package::open(&path).unwrap();
    let info = *package.chunk_info(ChunkId(0)).unwrap();
    let before = package.chunk(ChunkId(0)).unwrap().to_vec();
    let mut file = std::fs::OpenOptions::new().write(true).open(&path).unwrap();
    file.seek(SeekFrom::Start(info.offset)).unwrap();
    file.write_all(&[before[0] ^ 0xFF]).unwrap();
    file.sync_all().unwrap();
    // Already verified: served without rehashing (the map shows the new byte).
    let after = package.chunk(ChunkId(0)).unwrap();
    assert_eq!(after[0], before[0] ^ 0xFF);
    let err = package.verify().unwrap_err();
    assert!(
        matches!(
            err,
            PackageError::Corrupt {
                part: Part::Chunk(ChunkId(0)),
                ..
            }
        ),
        "{err}"
    );
    // A fresh open checks on first touch.
    let fresh = Package::open(&path).unwrap();
    assert!(fresh.chunk(ChunkId(0)).is_err());
}

// ---- committed fixtures --------------------------------------------------------------------

fn fixtures_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures")
}

/// Fixture name → whether its chunks are zstd-compressed. Add a line (and keep the old
/// files) whenever the format version changes.
const FIXTURES: &[(&str, bool)] = &[("v1.0-raw.motu", false), ("v1.0-zstd.motu", true)];

/// Every committed fixture opens, verifies and holds the sample contents. Regenerate with
/// `MOTU_UPDATE_FIXTURES=1 cargo test -p motu-package --test package fixtures`.
#[test]
fn fixtures_read_back_and_match_the_writer() {
    let update = std::env::var_os("MOTU_UPDATE_FIXTURES").is_some_and(|v| v == "1");
    let dir = fixtures_dir();
    let temp = tempfile::tempdir().unwrap();
    for &(name, zstd) in FIXTURES {
        let fresh = temp.path().join(name);
        let sample = write_sample(&fresh, zstd);
        let committed = dir.join(name);
        if update {
            std::fs::create_dir_all(&dir).unwrap();
            std::fs::copy(&fresh, &committed).unwrap();
        }
        let package = Package::open(&committed)
            .unwrap_or_else(|e| panic!("fixture {name}: {e} (MOTU_UPDATE_FIXTURES=1 rewrites)"));
        check_sample(&package, &sample);
        if !zstd {
            // Raw output is byte-stable: a diff here is a format change, bump the version.
            assert!(
                std::fs::read(&committed).unwrap() == std::fs::read(&fresh).unwrap(),
                "writer output differs from fixture {name}: a format change needs a new version"
            );
        }
    }
    // Every file in the fixtures directory is a package this reader accepts.
    let mut found = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "motu") {
            Package::open(&path).and_then(|p| p.verify()).unwrap();
            found += 1;
        }
    }
    assert!(found >= FIXTURES.len());
}

/// Recomputes the manifest and trailer checksums after an edit, so that the edit reaches the
/// structural validation instead of stopping at a checksum (what a malicious file would do).
fn reseal(bytes: &mut [u8]) {
    let trailer_start = bytes.len() - TRAILER_LEN as usize;
    let mut trailer: Trailer = bytemuck::pod_read_unaligned(&bytes[trailer_start..]);
    let manifest = (trailer.manifest_offset as usize)
        .checked_add(trailer.manifest_len as usize)
        .and_then(|end| bytes.get(trailer.manifest_offset as usize..end));
    if let Some(manifest) = manifest {
        trailer.manifest_checksum = format::checksum(manifest);
    }
    trailer.checksum = trailer.compute_checksum();
    bytes[trailer_start..].copy_from_slice(bytemuck::bytes_of(&trailer));
}

fn exercise(bytes: &[u8]) {
    let Ok(package) = Package::from_bytes(bytes) else {
        return;
    };
    for id in 0..package.chunk_count() {
        let _ = package.chunk(ChunkId(id)).map(|c| c.len());
        let _ = package.prefetch_chunk(ChunkId(id));
    }
    for kind in [NODES, TRANSFORMS, NAMES, SectionKind(77)] {
        let _ = package.section_as::<u32>(kind);
        let _ = package.section_as::<Transform>(kind);
    }
    let _ = package.verify();
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    /// Hostile manifests and trailers (checksums fixed up) give errors, never panics or
    /// out-of-bounds reads.
    #[test]
    fn resealed_manifest_edits_never_panic(
        edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6),
        in_trailer in any::<bool>(),
        zstd in any::<bool>(),
    ) {
        let mut bytes = if zstd { SAMPLE_ZSTD.with(Clone::clone) } else { SAMPLE_RAW.with(Clone::clone) };
        let layout = layout(&bytes);
        // The trailer's checksummed fields are its first 32 bytes.
        let range = if in_trailer { layout.trailer.start..layout.trailer.start + 32 } else { layout.manifest };
        for (index, value) in edits {
            let at = range.start + index.index(range.len());
            bytes[at] = value;
        }
        reseal(&mut bytes);
        exercise(&bytes);
    }
}

thread_local! {
    static SAMPLE_RAW: Vec<u8> = sample_bytes(false);
    static SAMPLE_ZSTD: Vec<u8> = sample_bytes(true);
}

#[test]
fn hostile_chunk_entries_are_rejected() {
    let good = sample_bytes(true);
    let layout = layout(&good);
    let package = Package::from_bytes(&good).unwrap();
    let zstd_id = package
        .chunks()
        .iter()
        .find(|c| c.codec == Codec::Zstd)
        .unwrap()
        .id;
    let entry_at = layout.manifest.start + 32 + zstd_id.0 as usize * 48;
    let raw_len = package.chunk_info(zstd_id).unwrap().raw_len;
    let cases: [(usize, u64, &str); 5] = [
        (0, 4097, "not page aligned"),                    // offset
        (0, u64::MAX - 10, "not page aligned"),           // offset + len overflows
        (16, 1 << 40, "raw length"),                      // raw_len over the format limit
        (16, 5, "zstd: Destination buffer is too small"), // raw_len below the data
        (16, raw_len + 100, "decompressed to"),           // raw_len above the data
    ];
    for (field, value, expected) in cases {
        let mut bad = good.clone();
        bad[entry_at + field..entry_at + field + 8].copy_from_slice(&value.to_le_bytes());
        reseal(&mut bad);
        let err = Package::from_bytes(&bad)
            .and_then(|p| p.chunk(zstd_id).map(|c| c.len()))
            .unwrap_err();
        assert!(err.to_string().contains(expected), "{field}={value}: {err}");
        assert!(
            err.to_string().contains(&format!("chunk {}", zstd_id.0)),
            "{err}"
        );
    }
}

#[test]
fn read_back_and_oversized_blobs() {
    for zstd_level in [None, Some(3)] {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("rb.motu");
        let opts = WriterOptions {
            target_chunk_bytes: 4096,
            zstd_level,
            direct_io: false,
        };
        let mut w = PackageWriter::create(&path, opts).unwrap();
        let s = w.open_stream(1, 2);
        let small: Vec<u8> = (0..1000u32).map(|i| (i % 251) as u8).collect();
        let a = w.append(s, &small, 16).unwrap();
        // Still in the open chunk.
        assert_eq!(
            w.read_back(a.chunk, a.offset_in_chunk, a.len_bytes)
                .unwrap(),
            small
        );
        let big: Vec<u8> = (0..20_000u32).map(|i| (i % 13) as u8).collect();
        let b = w.append(s, &big, 16).unwrap();
        assert_ne!(a.chunk, b.chunk, "an oversized blob gets its own chunk");
        // Both sealed now: read back from the temp file (decompressing if needed).
        assert_eq!(
            w.read_back(a.chunk, a.offset_in_chunk, a.len_bytes)
                .unwrap(),
            small
        );
        assert_eq!(w.read_back(b.chunk, 0, b.len_bytes).unwrap(), big);
        assert!(w.read_back(b.chunk, 19_999, 2).is_err());
        // Into a buffer that held another chunk (longer, then shorter): the chunk alone.
        let mut buf = vec![7u8; 50_000];
        w.read_back_chunk_into(b.chunk, &mut buf).unwrap();
        assert_eq!(buf, w.read_back_chunk(b.chunk).unwrap());
        assert_eq!(&buf[..big.len()], &big[..]);
        w.read_back_chunk_into(a.chunk, &mut buf).unwrap();
        assert_eq!(buf, w.read_back_chunk(a.chunk).unwrap());
        assert_eq!(
            &buf[a.offset_in_chunk as usize..][..small.len()],
            &small[..]
        );
        // A buffer shorter than the chunk, holding other bytes (not zeroed before the read).
        let mut short = vec![9u8; 100];
        w.read_back_chunk_into(b.chunk, &mut short).unwrap();
        assert_eq!(short, big);
        w.close_stream(s).unwrap();
        w.finish().unwrap();
        let p = Package::open(&path).unwrap();
        assert_eq!(&p.chunk(b.chunk).unwrap()[..], &big[..]);
        p.verify().unwrap();
    }
}

#[test]
fn a_section_written_piece_by_piece_reads_back_like_one_added_whole() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a.motu"), dir.path().join("b.motu"));
    let data: Vec<u8> = (0..4096u32).flat_map(|i| (i * 7).to_le_bytes()).collect();
    let mut whole = PackageWriter::create(&a, WriterOptions::default()).unwrap();
    whole.add_section(NODES, "nodes", 4, &data).unwrap();
    whole.finish().unwrap();
    let mut pieces = PackageWriter::create(&b, WriterOptions::default()).unwrap();
    let mut section = pieces.begin_section(NODES, "nodes", 4).unwrap();
    for part in data.chunks(1000) {
        section.write(part).unwrap();
    }
    assert_eq!(section.len_bytes(), data.len() as u64);
    section.finish().unwrap();
    pieces.finish().unwrap();
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    let package = Package::open(&b).unwrap();
    assert_eq!(package.section_info(NODES).unwrap().count, 4096);

    // A section left unfinished (or not a whole number of elements) fails the package: it is
    // never finished half-listed.
    let c = dir.path().join("c.motu");
    let mut w = PackageWriter::create(&c, WriterOptions::default()).unwrap();
    let mut section = w.begin_section(NODES, "nodes", 4).unwrap();
    section.write(&[1, 2, 3]).unwrap();
    assert!(section.finish().is_err());
    assert!(w.finish().is_err());
    assert!(!c.exists());
    let mut w = PackageWriter::create(&c, WriterOptions::default()).unwrap();
    drop(w.begin_section(NODES, "nodes", 4).unwrap());
    assert!(w.finish().is_err());
    assert!(!c.exists());
}

/// A blob filled in place lands where the same bytes appended would, with the same bytes
/// around it (alignment gaps zero), in a shared chunk, a new one and one of its own.
#[test]
fn blobs_filled_in_place_equal_blobs_appended() {
    let blobs = [
        noise(1, 10),
        noise(2, 10),
        noise(3, 930),
        noise(4, 1001),
        ramp(7),
    ];
    let aligns = [1, 64, 8, 1, 16];
    let dir = tempfile::tempdir().unwrap();
    let mut packages = Vec::new();
    for filled in [false, true] {
        let path = dir.path().join(format!("{filled}.motu"));
        let mut writer = PackageWriter::create(
            &path,
            WriterOptions {
                target_chunk_bytes: 1000,
                zstd_level: None,
                direct_io: false,
            },
        )
        .unwrap();
        let stream = writer.open_stream(0, 0);
        let locators: Vec<Locator> = blobs
            .iter()
            .zip(aligns)
            .map(|(b, align)| {
                if filled {
                    writer
                        .append_with(stream, b.len() as u64, align, &mut |out| {
                            out.extend_from_slice(b)
                        })
                        .unwrap()
                } else {
                    writer.append(stream, b, align).unwrap()
                }
            })
            .collect();
        writer.close_stream(stream).unwrap();
        writer.finish().unwrap();
        packages.push((locators, Package::open(&path).unwrap()));
    }
    let ((appended, a), (filled, f)) = (&packages[0], &packages[1]);
    assert_eq!(appended, filled);
    assert_eq!(appended.iter().map(|l| l.chunk.0).max(), Some(3));
    for id in 0..4 {
        assert_eq!(
            a.chunk(ChunkId(id)).unwrap()[..],
            f.chunk(ChunkId(id)).unwrap()[..]
        );
    }
    let last = filled[4];
    let chunk = f.chunk(last.chunk).unwrap();
    let at = last.offset_in_chunk as usize;
    assert_eq!(&chunk[at..at + 7], &ramp(7)[..]);
}

/// A fill that pushes other than the length it promised fails the append and the writer.
#[test]
fn a_fill_of_the_wrong_length_fails_the_writer() {
    let dir = tempfile::tempdir().unwrap();
    let mut writer =
        PackageWriter::create(dir.path().join("a.motu"), WriterOptions::default()).unwrap();
    let stream = writer.open_stream(0, 0);
    let short = writer.append_with(stream, 8, 1, &mut |out| out.extend_from_slice(&[1; 7]));
    assert!(
        matches!(short, Err(PackageError::InvalidArgument(_))),
        "{short:?}"
    );
    assert!(writer.append(stream, &[1; 8], 1).is_err());
}
