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

impl SourceBytes {
    /// Open `path`: memory-map it, or stream-decompress it when its name ends in `.gz`.
    ///
    /// This is the only place the crate maps files.
    pub fn open(path: &Path) -> std::io::Result<Self> {
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
        // concurrent truncation could fault, which we accept as documented.
        let map = unsafe { memmap2::Mmap::map(&file)? };
        Ok(SourceBytes::Mapped(map))
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
mod tests {
    use super::*;
    use std::io::Write;

    #[test]
    fn plain_and_gz() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.pbrt");
        std::fs::write(&p, b"WorldBegin").unwrap();
        assert_eq!(SourceBytes::open(&p).unwrap().bytes(), b"WorldBegin");
        let gz = dir.path().join("a.pbrt.gz");
        let mut enc =
            flate2::write::GzEncoder::new(File::create(&gz).unwrap(), flate2::Compression::fast());
        enc.write_all(b"Shape \"sphere\"").unwrap();
        enc.finish().unwrap();
        assert_eq!(SourceBytes::open(&gz).unwrap().bytes(), b"Shape \"sphere\"");
        let empty = dir.path().join("e.pbrt");
        std::fs::write(&empty, b"").unwrap();
        assert!(SourceBytes::open(&empty).unwrap().bytes().is_empty());
        assert!(SourceBytes::open(&dir.path().join("missing.pbrt")).is_err());
    }
}
