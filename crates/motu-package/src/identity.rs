//! Which file a path names, for the rule that an output never replaces an input: an existing
//! file by device and inode (hard links and symlinks to one file are one file).

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
