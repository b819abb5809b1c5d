use std::ffi::OsString;
use std::fs;
use std::io::{Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use super::*;
use crate::compat::AnyDevice;
use crate::entry::ENTRY_HEADER_BYTES;
use crate::entry::{temp_prefix, TEMP_SUFFIX};
use crate::stats::WarningReason;

fn key(i: u8) -> CacheKey {
    crate::key::CacheKeyBuilder::new("disk tests")
        .u32(i.into())
        .finish()
}

/// A fake serialized structure: a 32-byte header of `driver`, then `len` varied bytes.
fn blob(driver: u8, len: usize) -> Vec<u8> {
    let mut v = vec![driver; 32];
    v.extend((0..len).map(|i| (i * 31 + usize::from(driver)) as u8));
    v
}

fn driver(d: u8) -> impl Fn(&[u8; 32]) -> bool {
    move |h: &[u8; 32]| h.iter().all(|&b| b == d)
}

fn options(capacity_bytes: u64) -> DiskOptions {
    DiskOptions {
        capacity_bytes: Some(capacity_bytes),
        ..DiskOptions::default()
    }
}

fn open(dir: &Path, capacity_bytes: u64) -> DiskCache {
    DiskCache::open(dir, options(capacity_bytes))
}

/// Files under the cache directory, relative, sorted.
fn files(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in fs::read_dir(&d).unwrap().flatten() {
            if e.file_type().unwrap().is_dir() {
                stack.push(e.path());
            } else {
                out.push(
                    e.path()
                        .strip_prefix(dir)
                        .unwrap()
                        .to_string_lossy()
                        .into_owned(),
                );
            }
        }
    }
    out.sort();
    out
}

fn temp_files(dir: &Path) -> Vec<String> {
    files(dir)
        .into_iter()
        .filter(|f| f.ends_with(TEMP_SUFFIX))
        .collect()
}

fn set_mtime(path: &Path, t: SystemTime) {
    fs::File::options()
        .write(true)
        .open(path)
        .unwrap()
        .set_modified(t)
        .unwrap();
}

/// Whether this process can write where permissions say it may not (root in CI).
fn permissions_are_bypassed(dir: &Path) -> bool {
    fs::write(dir.join("probe"), b"x").is_ok()
}

#[test]
fn round_trip_and_a_new_open_finds_the_entries() {
    let dir = tempfile::tempdir().unwrap();
    let mut c = open(dir.path(), 1 << 20);
    assert!(c.writable());
    assert!(c.get(&key(1), &driver(1)).is_none());
    assert!(c.put(&key(1), &blob(1, 1000)));
    assert!(c.put(&key(2), &blob(1, 10)));
    assert_eq!(
        c.get(&key(1), &driver(1)).as_deref(),
        Some(&blob(1, 1000)[..])
    );
    let path = c.entry_path(&key(1));
    assert_eq!(
        fs::metadata(&path).unwrap().len(),
        (ENTRY_HEADER_BYTES + 1032) as u64
    );
    let s = c.stats();
    assert_eq!((s.hits, s.misses, s.written, s.entries), (1, 1, 2, 2));
    assert_eq!(s.bytes, (2 * ENTRY_HEADER_BYTES + 1032 + 42) as u64);
    assert_eq!(s.warnings.total(), 0);
    assert!(temp_files(dir.path()).is_empty());

    let mut again = open(dir.path(), 1 << 20);
    let s = again.stats();
    assert_eq!(
        (s.found_at_open, s.entries, s.bytes),
        (2, 2, c.stats().bytes)
    );
    assert_eq!(
        again.get(&key(2), &driver(1)).as_deref(),
        Some(&blob(1, 10)[..])
    );
}

#[test]
fn an_entry_written_by_another_process_after_open_is_found() {
    let dir = tempfile::tempdir().unwrap();
    let mut reader = open(dir.path(), 1 << 20);
    let mut writer = open(dir.path(), 1 << 20);
    assert!(writer.put(&key(3), &blob(2, 64)));
    assert!(!reader.contains(&key(3)));
    assert_eq!(
        reader.get(&key(3), &driver(2)).as_deref(),
        Some(&blob(2, 64)[..])
    );
    assert!(reader.contains(&key(3)), "indexed once read");
}

#[test]
fn two_writers_of_one_key_both_leave_a_whole_entry() {
    let dir = tempfile::tempdir().unwrap();
    let mut a = open(dir.path(), 1 << 20);
    let mut b = open(dir.path(), 1 << 20);
    assert!(a.put(&key(4), &blob(3, 100)));
    assert!(b.put(&key(4), &blob(3, 200)));
    // The last rename wins; whichever it is, it is whole and valid.
    let got = a.get(&key(4), &driver(3)).unwrap();
    assert_eq!(&*got, &blob(3, 200)[..]);
    assert_eq!(files(dir.path()).len(), 1);
}

#[test]
fn evicts_least_recently_used_within_the_bound() {
    let dir = tempfile::tempdir().unwrap();
    let entry = (ENTRY_HEADER_BYTES + 32 + 100) as u64;
    let mut c = open(dir.path(), 3 * entry);
    for i in 0..3 {
        assert!(c.put(&key(i), &blob(1, 100)));
    }
    assert!(c.get(&key(0), &AnyDevice).is_some()); // 1 is now the least recent
    assert!(c.put(&key(3), &blob(1, 100)));
    assert!(
        !c.entry_path(&key(1)).exists(),
        "the least recent file is removed"
    );
    for i in [0, 2, 3] {
        assert!(c.entry_path(&key(i)).exists(), "{i}");
    }
    let s = c.stats();
    assert_eq!((s.entries, s.bytes, s.evicted_entries), (3, 3 * entry, 1));
    assert!(s.bytes <= s.capacity_bytes);

    // An entry larger than the bound is not written, and evicts nothing.
    assert!(!c.put(&key(9), &blob(1, 4 * entry as usize)));
    assert_eq!(c.stats().skipped_writes, 1);
    assert_eq!(c.stats().entries, 3);
    assert!(c.writable(), "too large is not a failure");
}

#[test]
fn recency_survives_the_process_through_file_times() {
    let dir = tempfile::tempdir().unwrap();
    let entry = (ENTRY_HEADER_BYTES + 32 + 100) as u64;
    let mut c = open(dir.path(), 1 << 20);
    for i in 0..4 {
        assert!(c.put(&key(i), &blob(1, 100)));
    }
    // Oldest first: 2, 0, 3, 1 (as if read in that order by earlier processes).
    let base = SystemTime::now() - Duration::from_secs(3600);
    for (age, i) in [2u8, 0, 3, 1].iter().enumerate() {
        set_mtime(
            &c.entry_path(&key(*i)),
            base + Duration::from_secs(age as u64),
        );
    }
    drop(c);
    // A smaller bound at the next open keeps the two most recent.
    let mut c = open(dir.path(), 2 * entry);
    let s = c.stats();
    assert_eq!((s.found_at_open, s.entries, s.evicted_entries), (4, 2, 2));
    for (i, kept) in [(0, false), (1, true), (2, false), (3, true)] {
        assert_eq!(c.entry_path(&key(i)).exists(), kept, "{i}");
    }
    // A hit touches the file: it is the most recent for the next process too.
    let before = fs::metadata(c.entry_path(&key(3)))
        .unwrap()
        .modified()
        .unwrap();
    assert!(c.get(&key(3), &AnyDevice).is_some());
    let after = fs::metadata(c.entry_path(&key(3)))
        .unwrap()
        .modified()
        .unwrap();
    assert!(after > before);
}

/// Writes one entry, damages its file with `damage`, and checks that the next read is a miss
/// counted under `reason`, that the file is gone and that the key can be written again.
fn check_bad_entry(damage: impl FnOnce(&Path), compat: &dyn Compatibility, reason: WarningReason) {
    let dir = tempfile::tempdir().unwrap();
    let mut c = open(dir.path(), 1 << 20);
    assert!(c.put(&key(1), &blob(1, 500)));
    let path = c.entry_path(&key(1));
    damage(&path);
    // A fresh open (scan included) and the same instance both refuse it.
    let mut fresh = open(dir.path(), 1 << 20);
    assert!(fresh.get(&key(1), compat).is_none(), "{reason}");
    let s = fresh.stats();
    assert_eq!(s.warnings.get(reason), 1, "{reason}: {:?}", s.warnings);
    assert_eq!(s.warnings.total(), 1, "{reason}");
    assert_eq!((s.misses, s.hits, s.removed_bad), (1, 0, 1), "{reason}");
    assert!(!path.exists(), "{reason}: the bad file is removed");
    assert!(!fresh.contains(&key(1)));
    assert!(c.get(&key(1), compat).is_none(), "{reason}");
    assert!(fresh.put(&key(1), &blob(1, 500)));
    assert!(fresh.get(&key(1), &driver(1)).is_some());
}

fn flip(path: &Path, at: u64) {
    let mut f = fs::File::options()
        .read(true)
        .write(true)
        .open(path)
        .unwrap();
    let mut b = [0u8];
    f.seek(SeekFrom::Start(at)).unwrap();
    std::io::Read::read_exact(&mut f, &mut b).unwrap();
    f.seek(SeekFrom::Start(at)).unwrap();
    f.write_all(&[b[0] ^ 0x01]).unwrap();
}

#[test]
fn a_corrupted_byte_is_a_counted_miss_and_the_file_is_removed() {
    let blob_byte = ENTRY_HEADER_BYTES as u64 + 300;
    check_bad_entry(|p| flip(p, blob_byte), &driver(1), WarningReason::Corrupt);
    check_bad_entry(|p| flip(p, 50), &driver(1), WarningReason::Corrupt); // blob length
    check_bad_entry(|p| flip(p, 0), &driver(1), WarningReason::Corrupt); // magic
    check_bad_entry(
        |p| {
            fs::OpenOptions::new()
                .append(true)
                .open(p)
                .unwrap()
                .write_all(b"x")
                .unwrap()
        },
        &driver(1),
        WarningReason::Corrupt,
    );
}

#[test]
fn a_truncated_file_is_a_counted_miss_and_the_file_is_removed() {
    let cut = |len: u64| {
        move |p: &Path| {
            fs::File::options()
                .write(true)
                .open(p)
                .unwrap()
                .set_len(len)
                .unwrap()
        }
    };
    check_bad_entry(cut(500), &driver(1), WarningReason::Truncated);
    check_bad_entry(cut(10), &driver(1), WarningReason::Truncated);
    check_bad_entry(cut(0), &driver(1), WarningReason::Truncated);
}

#[test]
fn an_entry_renamed_to_another_key_is_foreign() {
    let dir = tempfile::tempdir().unwrap();
    let mut c = open(dir.path(), 1 << 20);
    assert!(c.put(&key(7), &blob(1, 500)));
    let other = key(1);
    let target = c.entry_path(&other);
    fs::create_dir_all(target.parent().unwrap()).unwrap();
    fs::rename(c.entry_path(&key(7)), &target).unwrap();
    let mut fresh = open(dir.path(), 1 << 20);
    assert!(fresh.get(&other, &driver(1)).is_none());
    let s = fresh.stats();
    assert_eq!(
        (s.warnings.foreign, s.warnings.total(), s.removed_bad),
        (1, 1, 1)
    );
    assert!(!target.exists());
}

#[test]
fn an_incompatible_header_is_a_counted_miss_and_the_file_is_removed() {
    check_bad_entry(|_| {}, &driver(2), WarningReason::Incompatible);
    check_bad_entry(|_| {}, &|_: &[u8; 32]| false, WarningReason::Incompatible);
}

#[test]
fn a_blob_without_a_serialization_header_is_never_written() {
    let dir = tempfile::tempdir().unwrap();
    let mut c = open(dir.path(), 1 << 20);
    assert!(!c.put(&key(1), &[1; 31]));
    assert_eq!(c.stats().skipped_writes, 1);
    assert!(c.writable());
    assert!(files(dir.path()).is_empty());
}

#[test]
fn a_bad_entry_replaced_since_it_was_read_is_kept() {
    let dir = tempfile::tempdir().unwrap();
    let mut c = open(dir.path(), 1 << 20);
    assert!(c.put(&key(1), &blob(1, 100)));
    let path = c.entry_path(&key(1));
    let read = fs::metadata(&path).ok().as_ref().and_then(file_id);
    // Another process renames a good entry over the bad one between the read and the removal.
    let mut other = open(dir.path(), 1 << 20);
    assert!(other.put(&key(1), &blob(1, 100)));
    c.bad_entry(&path, EntryError::Incompatible, read);
    assert!(path.exists());
    assert_eq!(c.stats().removed_bad, 0);
}

#[test]
fn io_errors_map_to_reasons() {
    use std::io::{Error, ErrorKind};
    for (kind, reason) in [
        (ErrorKind::PermissionDenied, WarningReason::ReadOnly),
        (ErrorKind::ReadOnlyFilesystem, WarningReason::ReadOnly),
        (ErrorKind::StorageFull, WarningReason::Full),
        (ErrorKind::QuotaExceeded, WarningReason::Full),
        (ErrorKind::NotADirectory, WarningReason::Io),
        (ErrorKind::Other, WarningReason::Io),
    ] {
        assert_eq!(io_reason(&Error::from(kind)), reason, "{kind:?}");
    }
    // What the kernel says for a full disk and a read-only filesystem.
    assert_eq!(
        io_reason(&Error::from_raw_os_error(28)),
        WarningReason::Full
    ); // ENOSPC
    assert_eq!(
        io_reason(&Error::from_raw_os_error(30)),
        WarningReason::ReadOnly
    ); // EROFS
    assert_eq!(
        io_reason(&Error::from_raw_os_error(13)),
        WarningReason::ReadOnly
    ); // EACCES
}

/// Checks a cache whose writes fail: `put` returns without error or panic, the warning is
/// counted once under `reason`, writes are off, no temp file is left, reads still work.
fn check_write_failure(c: &mut DiskCache, dir: &Path, reason: WarningReason) {
    let before = c.stats().warnings.get(reason);
    assert!(!c.put(&key(1), &blob(1, 100)));
    assert!(!c.writable());
    let s = c.stats();
    assert_eq!(s.warnings.get(reason), before + 1, "{:?}", s.warnings);
    assert!(!c.put(&key(2), &blob(1, 100)), "writes stay off");
    assert_eq!(
        c.stats().warnings.get(reason),
        before + 1,
        "warned once, not per write"
    );
    assert!(c.stats().skipped_writes >= 1);
    if dir.is_dir() {
        assert!(temp_files(dir).is_empty(), "{:?}", files(dir));
    }
}

#[test]
fn a_full_disk_is_a_counted_warning_and_reads_go_on() {
    let dir = tempfile::tempdir().unwrap();
    let mut good = open(dir.path(), 1 << 20);
    assert!(good.put(&key(0), &blob(1, 100)));
    let mut c = DiskCache::open(
        dir.path(),
        DiskOptions {
            fail_writes_with: Some(std::io::ErrorKind::StorageFull),
            ..options(1 << 20)
        },
    );
    check_write_failure(&mut c, dir.path(), WarningReason::Full);
    assert!(!c.entry_path(&key(1)).exists());
    assert!(c.get(&key(0), &driver(1)).is_some(), "reads go on");
}

#[test]
fn a_read_only_directory_is_a_counted_warning_never_an_error() {
    // Simulated: the error a read-only directory gives an unprivileged user.
    let dir = tempfile::tempdir().unwrap();
    let mut c = DiskCache::open(
        dir.path(),
        DiskOptions {
            fail_writes_with: Some(std::io::ErrorKind::PermissionDenied),
            ..options(1 << 20)
        },
    );
    check_write_failure(&mut c, dir.path(), WarningReason::ReadOnly);

    // Real: a directory of mode 0555 with an entry in it.
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("cache");
    let mut writer = open(&root, 1 << 20);
    assert!(writer.put(&key(0), &blob(1, 100)));
    let shard = writer.entry_path(&key(1)).parent().unwrap().to_path_buf();
    let read_only = |p: &Path, mode| {
        use std::os::unix::fs::PermissionsExt;
        fs::set_permissions(p, fs::Permissions::from_mode(mode)).unwrap();
    };
    for p in [&root, &root.join(VERSION_DIR)] {
        read_only(p, 0o555);
    }
    if shard.exists() {
        read_only(&shard, 0o555);
    }
    let bypassed = permissions_are_bypassed(&root.join(VERSION_DIR));
    let mut c = open(&root, 1 << 20);
    if bypassed {
        // Root ignores the mode bits (CI): force the write failure another way below.
        eprintln!("running as root: mode 0555 does not stop writes; using a path under a file");
    } else {
        check_write_failure(&mut c, &root, WarningReason::ReadOnly);
        assert!(c.get(&key(0), &driver(1)).is_some(), "reads go on");
    }
    for p in [&root, &root.join(VERSION_DIR)] {
        read_only(p, 0o755);
    }

    // Real for root too: sysfs refuses new directories (EPERM, or EROFS where mounted ro).
    let sys = Path::new("/sys/motu-ascache-test-cache");
    if Path::new("/sys/kernel").is_dir() && !sys.exists() {
        let mut c = open(sys, 1 << 20);
        let _ = fs::remove_dir_all(sys); // never created; defensive
        assert!(!c.writable());
        assert_eq!(c.stats().warnings.read_only, 1, "{:?}", c.stats().warnings);
        assert!(!c.put(&key(1), &blob(1, 100)));
        assert!(c.get(&key(1), &driver(1)).is_none());
        assert_eq!(c.stats().warnings.total(), 1);
    } else {
        eprintln!("no sysfs: the /sys case is skipped");
    }

    // A cache directory that cannot be created (a path under a regular file): for everyone.
    let file = dir.path().join("a-file");
    fs::write(&file, b"not a directory").unwrap();
    let mut c = open(&file.join("cache"), 1 << 20);
    assert!(!c.writable());
    let s = c.stats();
    assert_eq!(s.warnings.io, 1, "{:?}", s.warnings);
    assert!(!c.put(&key(1), &blob(1, 100)));
    assert!(c.get(&key(1), &driver(1)).is_none());
    assert_eq!(c.stats().warnings.total(), 1);
}

#[test]
fn a_write_failure_after_open_turns_writes_off() {
    // The shard directory is a file: creating it fails on the first put, for everyone.
    let dir = tempfile::tempdir().unwrap();
    let mut c = open(dir.path(), 1 << 20);
    let shard = c.entry_path(&key(1)).parent().unwrap().to_path_buf();
    fs::write(&shard, b"in the way").unwrap();
    check_write_failure(&mut c, dir.path(), WarningReason::Io);
}

#[test]
fn stale_temp_files_are_removed_at_open_live_ones_never() {
    let dir = tempfile::tempdir().unwrap();
    let c = open(dir.path(), 1 << 20);
    let shard = c.entry_path(&key(1)).parent().unwrap().to_path_buf();
    fs::create_dir_all(&shard).unwrap();
    let old = SystemTime::now() - Duration::from_secs(3600);
    // A pid no process has (above the kernel's pid_max of 2^22).
    let dead = 4_000_000_000u32;
    let make = |pid: u32, tag: &str, mtime: SystemTime| -> PathBuf {
        let p = shard.join(format!("{}{tag}{TEMP_SUFFIX}", temp_prefix(&key(1), pid)));
        fs::write(&p, b"partial").unwrap();
        set_mtime(&p, mtime);
        p
    };
    let stale = make(dead, "aaaaaa", old);
    let young = make(dead, "bbbbbb", SystemTime::now());
    let live = make(1, "cccccc", old); // pid 1 always runs
    let own = make(std::process::id(), "dddddd", old);
    let other_name = shard.join("not-ours.tmp");
    fs::write(&other_name, b"x").unwrap();
    set_mtime(&other_name, old);

    let c = open(dir.path(), 1 << 20);
    assert_eq!(c.stats().stale_temp_files_removed, 1);
    assert!(!stale.exists());
    for kept in [&young, &live, &own, &other_name] {
        assert!(kept.exists(), "{}", kept.display());
    }
    assert_eq!(c.stats().entries, 0, "temp files are not entries");
}

#[test]
fn an_oversized_entry_found_at_open_is_removed() {
    let dir = tempfile::tempdir().unwrap();
    let mut c = open(dir.path(), 1 << 20);
    assert!(c.put(&key(1), &blob(1, 1000)));
    let c = open(dir.path(), 500);
    assert_eq!((c.stats().entries, c.stats().evicted_entries), (0, 1));
    assert!(!c.entry_path(&key(1)).exists());
}

#[test]
fn default_directory_from_the_environment() {
    let env = |vars: &[(&str, &str)]| {
        let vars: Vec<(String, OsString)> = vars
            .iter()
            .map(|(k, v)| (k.to_string(), OsString::from(v)))
            .collect();
        dir_from_env(move |name| vars.iter().find(|(k, _)| k == name).map(|(_, v)| v.clone()))
    };
    let all = [
        ("MOTU_AS_CACHE", "/m"),
        ("XDG_CACHE_HOME", "/x"),
        ("HOME", "/h"),
    ];
    assert_eq!(env(&all), Some(PathBuf::from("/m")));
    assert_eq!(env(&all[1..]), Some(PathBuf::from("/x/motu/as-cache")));
    assert_eq!(
        env(&all[2..]),
        Some(PathBuf::from("/h/.cache/motu/as-cache"))
    );
    assert_eq!(env(&[]), None);
    // Empty values are unset; a relative XDG_CACHE_HOME is invalid (XDG spec).
    assert_eq!(
        env(&[
            ("MOTU_AS_CACHE", ""),
            ("XDG_CACHE_HOME", "rel"),
            ("HOME", "/h")
        ]),
        Some(PathBuf::from("/h/.cache/motu/as-cache"))
    );
    assert_eq!(
        env(&[("MOTU_AS_CACHE", "rel/dir")]),
        Some(PathBuf::from("rel/dir"))
    );
    // The process's own environment follows the same rule.
    assert_eq!(default_dir(), dir_from_env(|n| std::env::var_os(n)));
}

#[test]
fn default_bound_is_the_smaller_of_the_constant_and_half_the_free_space() {
    const GIB: u64 = 1 << 30;
    assert_eq!(
        default_disk_capacity_bytes(0, None),
        DEFAULT_DISK_CAPACITY_BYTES
    );
    assert_eq!(default_disk_capacity_bytes(0, Some(1000 * GIB)), 32 * GIB);
    assert_eq!(default_disk_capacity_bytes(0, Some(10 * GIB)), 5 * GIB);
    assert_eq!(
        default_disk_capacity_bytes(3 * GIB, Some(10 * GIB)),
        8 * GIB
    );
    assert_eq!(
        default_disk_capacity_bytes(u64::MAX, Some(u64::MAX)),
        32 * GIB
    );
    let dir = tempfile::tempdir().unwrap();
    let free = filesystem_free_bytes(dir.path());
    assert!(
        free.is_some_and(|f| f > 0),
        "statvfs on a temp dir: {free:?}"
    );
    let c = DiskCache::open(dir.path(), DiskOptions::default());
    // Free space moves between the two reads (other writers on the machine): within 1 GiB.
    let expected = default_disk_capacity_bytes(0, free);
    let got = c.stats().capacity_bytes;
    assert!(got <= DEFAULT_DISK_CAPACITY_BYTES);
    assert!(got.abs_diff(expected) < GIB, "{got} vs {expected}");
}

#[test]
fn an_unreadable_entry_is_a_counted_miss_warned_once() {
    let dir = tempfile::tempdir().unwrap();
    let mut c = open(dir.path(), 1 << 20);
    // A directory where the entry's file should be: opens, but reading it fails (EISDIR).
    fs::create_dir_all(c.entry_path(&key(1))).unwrap();
    assert!(c.get(&key(1), &AnyDevice).is_none());
    assert!(c.get(&key(1), &AnyDevice).is_none());
    let s = c.stats();
    assert_eq!((s.warnings.io, s.misses, s.removed_bad), (2, 2, 0));
    assert!(c.writable(), "a failed read leaves writes on");
    assert!(c.entry_path(&key(1)).is_dir(), "not ours to remove");
}

mod prop {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]
        /// On disk, not only in the index: the entries' files never exceed the bound, the
        /// files are exactly the indexed entries, every entry just written or read is kept,
        /// and every read returns what was last written under its key.
        #[test]
        fn files_stay_within_the_bound_and_match_the_index(
            capacity_entries in 1u64..5,
            ops in proptest::collection::vec((any::<bool>(), 0u8..8, 0usize..300), 1..40),
        ) {
            let dir = tempfile::tempdir().unwrap();
            let capacity = capacity_entries * (ENTRY_HEADER_BYTES as u64 + 32 + 300);
            let mut c = open(dir.path(), capacity);
            let mut last: std::collections::HashMap<u8, Vec<u8>> = Default::default();
            for (write, k, len) in ops {
                if write {
                    let b = blob(k, len);
                    prop_assert!(c.put(&key(k), &b));
                    last.insert(k, b);
                    prop_assert!(c.contains(&key(k)));
                } else if let Some(got) = c.get(&key(k), &driver(k)) {
                    prop_assert_eq!(Some(&got[..]), last.get(&k).map(|v| &v[..]));
                    prop_assert!(c.contains(&key(k)));
                }
                let on_disk: Vec<String> = files(dir.path());
                let bytes: u64 = on_disk
                    .iter()
                    .map(|f| fs::metadata(dir.path().join(f)).unwrap().len())
                    .sum();
                let s = c.stats();
                prop_assert!(bytes <= capacity, "{} > {}", bytes, capacity);
                prop_assert_eq!(bytes, s.bytes);
                prop_assert_eq!(on_disk.len() as u64, s.entries);
                prop_assert_eq!(s.warnings.total(), 0);
            }
        }
    }
}
