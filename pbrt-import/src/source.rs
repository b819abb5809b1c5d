//! Scene file bytes: memory-mapped, or decompressed into memory for `.gz`.

use std::fs::File;
use std::io::Read;
use std::path::Path;

/// The bytes of one input file.
pub enum SourceBytes {
    /// Memory-mapped plain file.
    Mapped(memmap2::Mmap),
    /// Decompressed (`.gz`) or empty file contents.
    Owned(Vec<u8>),
}

/// What a referenced path is, for messages that say so (a directory, FIFO or device named as
/// an input is an error of its own, not a "missing file").
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FileKind {
    Regular,
    Missing,
    /// Exists but cannot be read as a file: `a directory`, `a FIFO`, `a symlink loop`, ...
    Other(&'static str),
}

/// Classifies `path` without opening it (opening a FIFO would block).
pub fn classify(path: &Path) -> FileKind {
    match std::fs::metadata(path) {
        Ok(m) => {
            let t = m.file_type();
            if t.is_file() {
                return FileKind::Regular;
            }
            #[cfg(unix)]
            {
                use std::os::unix::fs::FileTypeExt;
                if t.is_fifo() {
                    return FileKind::Other("a FIFO");
                }
                if t.is_char_device() {
                    return FileKind::Other("a character device");
                }
                if t.is_block_device() {
                    return FileKind::Other("a block device");
                }
                if t.is_socket() {
                    return FileKind::Other("a socket");
                }
            }
            if t.is_dir() {
                FileKind::Other("a directory")
            } else {
                FileKind::Other("not a regular file")
            }
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            if std::fs::symlink_metadata(path).is_ok() {
                FileKind::Other("a dangling symbolic link")
            } else {
                FileKind::Missing
            }
        }
        // ELOOP (40 on Linux): the name resolves through a cycle of symbolic links.
        Err(e) if e.raw_os_error() == Some(40) => FileKind::Other("a symbolic-link loop"),
        Err(e) if e.kind() == std::io::ErrorKind::PermissionDenied => {
            FileKind::Other("unreadable (permission denied)")
        }
        Err(_) => FileKind::Other("unreadable"),
    }
}

/// The check every scene-side input path (pbrt, PLY, OBJ, MTL, spectrum and texture files)
/// passes before it is opened: a regular file of at most `max_bytes` when given. Returns its
/// size; the error names what it is instead. `motu_package::identity::check_input` is the
/// same check for the other inputs (this crate depends on no workspace crate), with the same
/// words for every kind.
pub fn check_input(path: &Path, max_bytes: Option<u64>) -> std::io::Result<u64> {
    use std::io::{Error, ErrorKind};
    match classify(path) {
        FileKind::Regular => {
            let bytes = std::fs::metadata(path)?.len();
            match max_bytes {
                Some(max) if bytes > max => Err(Error::new(
                    ErrorKind::InvalidData,
                    format!("{bytes} bytes, more than the {max} bytes this input may have"),
                )),
                _ => Ok(bytes),
            }
        }
        FileKind::Missing => Err(Error::new(ErrorKind::NotFound, "no such file")),
        FileKind::Other(what) => Err(Error::new(
            ErrorKind::InvalidInput,
            format!("{what}, not a regular file"),
        )),
    }
}

impl SourceBytes {
    /// Open `path`: memory-map it, or stream-decompress it when its name ends in `.gz`.
    /// Anything but a regular file is refused before opening (a FIFO would block, a
    /// directory or device cannot be mapped).
    ///
    /// This is the only place the crate maps files.
    pub fn open(path: &Path) -> std::io::Result<Self> {
        match classify(path) {
            FileKind::Regular | FileKind::Missing => {}
            FileKind::Other(what) => {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::InvalidInput,
                    format!("{what}, not a regular file"),
                ))
            }
        }
        let file = File::open(path)?;
        if path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("gz"))
        {
            let mut out = Vec::new();
            flate2::read::MultiGzDecoder::new(std::io::BufReader::new(file))
                .read_to_end(&mut out)?;
            return Ok(SourceBytes::Owned(out));
        }
        if file.metadata()?.len() == 0 {
            // Mapping an empty file fails on some platforms.
            return Ok(SourceBytes::Owned(Vec::new()));
        }
        // SAFETY: the map is read-only and private to this process; scene files are inputs
        // that nobody is expected to truncate while we read them (as in ripgrep). A
        // concurrent truncation faults (SIGBUS); the motu binary turns that into an error
        // naming the file (FORMAT.md, "Memory-mapped inputs").
        let map = unsafe { memmap2::Mmap::map(&file)? };
        Ok(SourceBytes::Mapped(map))
    }

    /// Drops the pages of a mapped file's bytes `start..end` from this process's resident set
    /// (a no-op for owned bytes): a parser that has read them calls it so a large file does
    /// not stay resident whole while it is parsed. They stay in the page cache and fault back
    /// in, unchanged, if read again. A failed hint costs only memory and is ignored.
    pub fn release(&self, start: usize, end: usize) {
        if let SourceBytes::Mapped(m) = self {
            let end = end.min(m.len());
            if start >= end {
                return;
            }
            // SAFETY: the map is read-only (nothing private to discard): MADV_DONTNEED only
            // unmaps its pages, and later reads fault the file's same bytes back in (a file
            // truncated meanwhile faults SIGBUS, as any read of the map would; see `open`).
            let _ = unsafe {
                m.unchecked_advise_range(memmap2::UncheckedAdvice::DontNeed, start, end - start)
            };
        }
    }

    /// The file contents.
    pub fn bytes(&self) -> &[u8] {
        match self {
            SourceBytes::Mapped(m) => m,
            SourceBytes::Owned(v) => v,
        }
    }
}

#[cfg(test)]
mod tests;
