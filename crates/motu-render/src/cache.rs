//! The structure cache a streamed render keeps built BLASes in (`--host-cache`, `--as-cache`,
//! `--no-as-cache`): its tiers from the settings, keyed by the package's content.

use std::path::PathBuf;

use motu_ascache::{AsCache, DiskCache, DiskOptions, HostCache};
use motu_pack::ScenePackage;

/// Where built structures are kept between evictions and processes.
#[derive(Clone, Debug, Default)]
pub struct CacheSettings {
    /// Bytes of serialised structures kept in host memory (`--host-cache`; `None`: a quarter
    /// of the memory available at start, `motu_ascache::default_host_cache_bytes`; 0: none).
    pub host_bytes: Option<u64>,
    pub dir: CacheDir,
}

/// The on-disk tier's directory.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub enum CacheDir {
    /// `$MOTU_AS_CACHE`, else `$XDG_CACHE_HOME/motu/as-cache`, else
    /// `~/.cache/motu/as-cache` (`motu_ascache::default_dir`); none when no home is known.
    #[default]
    Default,
    /// `--as-cache DIR`.
    At(PathBuf),
    /// `--no-as-cache`.
    Off,
}

impl CacheSettings {
    /// The cache for `pkg`'s structures (`None`: both tiers off).
    pub fn open(&self, pkg: &ScenePackage) -> Option<motu_gpu::StructureCache> {
        let host_bytes = self
            .host_bytes
            .unwrap_or_else(motu_ascache::default_host_cache_bytes);
        let dir = match &self.dir {
            CacheDir::Default => motu_ascache::default_dir(),
            CacheDir::At(p) => Some(p.clone()),
            CacheDir::Off => None,
        };
        if host_bytes == 0 && dir.is_none() {
            return None;
        }
        let disk = dir.map(|d| {
            tracing::info!(dir = %d.display(), "structure cache directory");
            DiskCache::open(
                d,
                DiskOptions {
                    fail_writes_with: simulated_write_failure(),
                    // Entries are written while the first frame builds: an fsync each held the
                    // cold frame (lavapipe, island 0.05: 4.4 s of its 6.4 s of building). An
                    // entry a power loss cut fails its checksum and is rebuilt with a warning.
                    sync: false,
                    // Files written beside the next builds instead of between them; the
                    // process writes what is queued before it exits.
                    background: true,
                    // The queue may run well ahead of the disk: `render` drops the cache (and
                    // waits for it) after writing its image, so a cold frame does not wait for
                    // the directory. Half the host cache's bytes, at least the default.
                    max_pending_bytes: (host_bytes / 2)
                        .max(motu_ascache::DEFAULT_MAX_PENDING_BYTES),
                    ..DiskOptions::default()
                },
            )
        });
        let cache = AsCache::new(HostCache::new(host_bytes), disk);
        Some(motu_gpu::StructureCache::new(cache, &package_identity(pkg)))
    }
}

/// Bytes that change whenever anything in `pkg` does: its format version and every chunk's and
/// section's checksum and length (the manifest's own content), so a key made from them names
/// this content, wherever the file lives.
pub fn package_identity(pkg: &ScenePackage) -> Vec<u8> {
    let p = pkg.package();
    let v = p.format_version();
    let mut out = Vec::with_capacity(16 + 24 * (p.chunks().len() + p.sections().len()));
    out.extend_from_slice(&v.major.to_le_bytes());
    out.extend_from_slice(&v.minor.to_le_bytes());
    for c in p.chunks() {
        out.extend_from_slice(&c.checksum.to_le_bytes());
        out.extend_from_slice(&c.raw_len.to_le_bytes());
        out.extend_from_slice(&c.stored_len.to_le_bytes());
    }
    for s in p.sections() {
        out.extend_from_slice(&s.checksum.to_le_bytes());
        out.extend_from_slice(&s.len_bytes.to_le_bytes());
        out.extend_from_slice(s.name.as_bytes());
    }
    out
}

/// `MOTU_AS_CACHE_SIMULATE=full`: every write to the cache directory fails as on a full disk
/// (tests of the warning; a real full disk cannot be made on demand).
fn simulated_write_failure() -> Option<std::io::ErrorKind> {
    (std::env::var_os("MOTU_AS_CACHE_SIMULATE").is_some_and(|v| v == "full"))
        .then_some(std::io::ErrorKind::StorageFull)
}
