//! Which file a path names, for the rule that an output never replaces an input: an existing
//! file by device and inode (hard links and symlinks to one file are one file); and the one
//! check every input path passes before it is opened ([`check_input`], [`open_input`]): a
//! regular file, within a size bound where one is known. Opening a FIFO blocks forever, a
//! device such as `/dev/zero` never ends, and a directory or symlink loop fails with a raw OS
//! error; each is named as what it is instead. (`pbrt-import`, which depends on no workspace
//! crate, keeps the same check for scene files: `pbrt_import::check_input`; the two name every
//! kind alike, `tests/tests/hardening3.rs` holds them to it.)

use std::path::{Path, PathBuf};

/// What a path names, for comparing inputs and outputs: an existing file by device and inode
/// (hard links and symlinks to one file are one file), a new one by its absolute path.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FileIdentity {
    Existing { dev: u64, ino: u64 },
    New(PathBuf),
}

impl FileIdentity {
    /// The identity of the file `meta` describes.
    pub fn of(meta: &std::fs::Metadata) -> Self {
        use std::os::unix::fs::MetadataExt;
        FileIdentity::Existing {
            dev: meta.dev(),
            ino: meta.ino(),
        }
    }

    /// Identity of an input (symlinks followed), `None` if it cannot be read.
    pub fn of_input(path: &Path) -> Option<Self> {
        std::fs::metadata(path).ok().map(|m| Self::of(&m))
    }
}

/// What an input path is, found without opening it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InputKind {
    /// A regular file (symlinks followed) of this many bytes.
    Regular {
        bytes: u64,
    },
    Missing,
    /// Exists but cannot be read as a file: `a directory`, `a FIFO`, `a symbolic-link loop`…
    Other(&'static str),
}

/// Classifies `path` without opening it (opening a FIFO would block).
pub fn classify_input(path: &Path) -> InputKind {
    match std::fs::metadata(path) {
        Ok(m) if m.is_file() => InputKind::Regular { bytes: m.len() },
        Ok(m) => InputKind::Other(describe_file_type(&m.file_type())),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            if std::fs::symlink_metadata(path).is_ok() {
                InputKind::Other("a dangling symbolic link")
            } else {
                InputKind::Missing
            }
        }
        // ELOOP (40 on Linux): the name resolves through a cycle of symbolic links.
        Err(e) if e.raw_os_error() == Some(40) => InputKind::Other("a symbolic-link loop"),
        Err(e) if e.kind() == std::io::ErrorKind::PermissionDenied => {
            InputKind::Other("unreadable (permission denied)")
        }
        Err(_) => InputKind::Other("unreadable"),
    }
}

/// The check every input path passes before it is opened: a regular file of at most
/// `max_bytes` (when given). Returns its size; the error's message names what it is instead
/// (`a FIFO, not a regular file`, `no such file`, `… bytes, more than …`).
pub fn check_input(path: &Path, max_bytes: Option<u64>) -> std::io::Result<u64> {
    use std::io::{Error, ErrorKind};
    match classify_input(path) {
        InputKind::Regular { bytes } => match max_bytes {
            Some(max) if bytes > max => Err(Error::new(
                ErrorKind::InvalidData,
                format!("{bytes} bytes, more than the {max} bytes this input may have"),
            )),
            _ => Ok(bytes),
        },
        InputKind::Missing => Err(Error::new(ErrorKind::NotFound, "no such file")),
        InputKind::Other(what) => Err(Error::new(
            ErrorKind::InvalidInput,
            format!("{what}, not a regular file"),
        )),
    }
}

/// [`check_input`], then opens the file and checks the opened file again (a path swapped for a
/// FIFO between the check and the open is refused, not read).
pub fn open_input(path: &Path, max_bytes: Option<u64>) -> std::io::Result<(std::fs::File, u64)> {
    check_input(path, max_bytes)?;
    let file = std::fs::File::open(path)?;
    let m = file.metadata()?;
    if !m.is_file() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("{}, not a regular file", describe_file_type(&m.file_type())),
        ));
    }
    if let Some(max) = max_bytes.filter(|&max| m.len() > max) {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!(
                "{} bytes, more than the {max} bytes this input may have",
                m.len()
            ),
        ));
    }
    Ok((file, m.len()))
}

/// `a directory`, `a symbolic link`, `a FIFO`, … for messages.
pub fn describe_file_type(t: &std::fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return "a FIFO";
        }
        if t.is_char_device() {
            return "a character device";
        }
        if t.is_block_device() {
            return "a block device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    if t.is_symlink() {
        "a symbolic link"
    } else if t.is_dir() {
        "a directory"
    } else if t.is_file() {
        "a regular file"
    } else {
        "not a regular file"
    }
}

#[cfg(test)]
mod tests;
