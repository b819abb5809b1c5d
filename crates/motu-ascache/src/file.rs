//! Writing one entry file and naming IO failures: below both the disk tier and its writer
//! thread, which each write entries.

use std::fs;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

use crate::entry::{
    encode_header, entry_path, shard_dir, temp_prefix, ENTRY_HEADER_BYTES, TEMP_SUFFIX,
};
use crate::key::CacheKey;
use crate::stats::WarningReason;

/// The warning an IO error counts as.
pub fn io_reason(e: &io::Error) -> WarningReason {
    match e.kind() {
        io::ErrorKind::PermissionDenied | io::ErrorKind::ReadOnlyFilesystem => {
            WarningReason::ReadOnly
        }
        io::ErrorKind::StorageFull | io::ErrorKind::QuotaExceeded | io::ErrorKind::FileTooLarge => {
            WarningReason::Full
        }
        _ => WarningReason::Io,
    }
}

/// Writes `blob` as `key`'s entry under `root` (temp file, optional fsync, rename over the
/// name): the entry's path and file bytes, or the path and the error (the temp file removed).
pub(crate) fn write_entry_file(
    root: &Path,
    key: &CacheKey,
    blob: &[u8],
    sync: bool,
    fail_with: Option<io::ErrorKind>,
) -> Result<(PathBuf, u64), (PathBuf, io::Error)> {
    let path = entry_path(root, key);
    let write = || -> io::Result<()> {
        let dir = shard_dir(root, key);
        create_private_dir_all(&dir)?;
        let mut temp = tempfile::Builder::new()
            .prefix(&temp_prefix(key, std::process::id()))
            .suffix(TEMP_SUFFIX)
            .tempfile_in(&dir)?;
        let file = temp.as_file_mut();
        file.write_all(&encode_header(key, blob))?;
        if let Some(kind) = fail_with {
            // Half the blob written, as a disk filling up mid-entry leaves it.
            file.write_all(&blob[..blob.len() / 2])?;
            return Err(io::Error::new(kind, "simulated write failure"));
        }
        file.write_all(blob)?;
        if sync {
            file.sync_all()?;
        }
        // rename(2) over the target: readers see the old entry or the new one, never a part.
        temp.persist(&path).map_err(|e| e.error)?;
        Ok(())
    };
    match write() {
        Ok(()) => Ok((path, blob.len() as u64 + ENTRY_HEADER_BYTES as u64)),
        Err(e) => Err((path, e)),
    }
}

/// Creates `dir` and its missing parents, private to the user (the blobs go to the driver).
pub(crate) fn create_private_dir_all(dir: &Path) -> io::Result<()> {
    let mut builder = fs::DirBuilder::new();
    builder.recursive(true);
    #[cfg(unix)]
    std::os::unix::fs::DirBuilderExt::mode(&mut builder, 0o700);
    builder.create(dir)
}
