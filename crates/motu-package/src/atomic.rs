//! Atomic output files: every file motu writes (packages, images, AOVs, stats, reports) is
//! written to a temp file beside its target, fsynced and renamed over the target, so a target
//! is either its old self or complete — never truncated or half-written.
//!
//! Temp files are named `.NAME.PID.RANDOM.motu-tmp` and registered for the life of the write,
//! so a process interrupted by a signal can remove its own ([`remove_registered_temp_files`],
//! called by the CLI's signal handler), and a later write to the same target removes those
//! whose process is gone ([`remove_stale_temp_files`]).

use std::ffi::OsString;
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use tempfile::NamedTempFile;

use crate::PackageError;

/// The suffix every motu temp file carries.
pub const TEMP_SUFFIX: &str = ".motu-tmp";

/// Temp files being written by this process (removed on signals), and whether that removal
/// has run: the process is exiting, and no temp file may be created after it.
struct Live {
    paths: Vec<PathBuf>,
    closing: bool,
}

static LIVE: Mutex<Live> = Mutex::new(Live {
    paths: Vec::new(),
    closing: false,
});

fn live() -> std::sync::MutexGuard<'static, Live> {
    // A panic while holding the lock leaves plain data: still usable.
    LIVE.lock().unwrap_or_else(|p| p.into_inner())
}

/// Removes every temp file this process is writing; returns how many were removed. For signal
/// handling threads: the process is about to exit, so the writers are abandoned, and
/// [`AtomicFile::create`] refuses from now on (a writer starting during the exit left its temp
/// file behind: an interrupted import's partition spill file, created just after the signal).
pub fn remove_registered_temp_files() -> usize {
    let paths = {
        let mut l = live();
        l.closing = true;
        std::mem::take(&mut l.paths)
    };
    paths
        .iter()
        .filter(|p| std::fs::remove_file(p).is_ok())
        .count()
}

/// `.NAME.` — the prefix of `target`'s temp files.
fn temp_prefix(target: &Path) -> Result<String, PackageError> {
    let name = target.file_name().ok_or_else(|| {
        PackageError::InvalidArgument(format!("{} has no file name", target.display()))
    })?;
    Ok(format!(".{}.", name.to_string_lossy()))
}

/// The directory a target lives in (`.` for a bare file name).
pub fn parent_dir(path: &Path) -> &Path {
    match path.parent() {
        Some(parent) if !parent.as_os_str().is_empty() => parent,
        _ => Path::new("."),
    }
}

/// The pid in a temp file name of `target` (`.NAME.PID.RANDOM.motu-tmp`), if it is one.
fn temp_owner(prefix: &str, file_name: &OsString) -> Option<u32> {
    let name = file_name.to_str()?;
    let middle = name.strip_prefix(prefix)?.strip_suffix(TEMP_SUFFIX)?;
    let (pid, random) = middle.split_once('.')?;
    if random.is_empty() || random.contains('.') {
        return None;
    }
    pid.parse().ok()
}

/// Whether process `pid` exists on this machine; `None` when that cannot be told (no /proc).
fn process_alive(pid: u32) -> Option<bool> {
    let proc = Path::new("/proc");
    if !proc.join("self").exists() {
        return None;
    }
    Some(proc.join(pid.to_string()).exists())
}

/// Removes temp files of `target` left by motu processes that no longer run (killed, or
/// interrupted by a signal they could not handle); returns the removed paths. Temp files of
/// live processes (a concurrent write to the same target) and files of other naming are kept.
pub fn remove_stale_temp_files(target: &Path) -> Result<Vec<PathBuf>, PackageError> {
    let prefix = temp_prefix(target)?;
    let dir = parent_dir(target);
    let mut removed = Vec::new();
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Ok(removed);
    };
    for e in entries.flatten() {
        let Some(pid) = temp_owner(&prefix, &e.file_name()) else {
            continue;
        };
        if pid == std::process::id() || process_alive(pid) != Some(false) {
            continue;
        }
        if e.file_type().is_ok_and(|t| t.is_file()) && std::fs::remove_file(e.path()).is_ok() {
            tracing::info!(path = %e.path().display(), pid, "removed a stale temp file");
            removed.push(e.path());
        }
    }
    Ok(removed)
}

/// A file written beside `target` and renamed over it by [`commit`](Self::commit). Dropping it
/// uncommitted removes the temp file and leaves the target untouched.
pub struct AtomicFile {
    target: PathBuf,
    temp: Option<NamedTempFile>,
}

impl std::fmt::Debug for AtomicFile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AtomicFile")
            .field("target", &self.target)
            .field("temp", &self.temp_path())
            .finish()
    }
}

impl AtomicFile {
    /// Creates the temp file beside `target` (removing stale temp files of `target` first).
    pub fn create(target: impl AsRef<Path>) -> Result<Self, PackageError> {
        let target = target.as_ref().to_path_buf();
        let prefix = format!("{}{}.", temp_prefix(&target)?, std::process::id());
        let _ = remove_stale_temp_files(&target);
        let mut builder = tempfile::Builder::new();
        builder.prefix(&prefix).suffix(TEMP_SUFFIX);
        // Temp files default to 0600; outputs are ordinary files (0666 minus the umask).
        #[cfg(unix)]
        builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666));
        // Created and registered under the lock, so a signal's removal either sees it or has
        // already run (then nothing is created).
        let mut l = live();
        if l.closing {
            let e = std::io::Error::new(
                std::io::ErrorKind::Interrupted,
                "the process is exiting on a signal",
            );
            return Err(PackageError::io("create temp file beside", &target, e));
        }
        let temp = builder
            .tempfile_in(parent_dir(&target))
            .map_err(|e| PackageError::io("create temp file beside", &target, e))?;
        l.paths.push(temp.path().to_path_buf());
        drop(l);
        Ok(AtomicFile {
            target,
            temp: Some(temp),
        })
    }

    /// Path of the temp file (removed on drop, renamed by `commit`).
    pub fn temp_path(&self) -> Option<&Path> {
        self.temp.as_ref().map(|t| t.path())
    }

    pub fn target(&self) -> &Path {
        &self.target
    }

    /// The open temp file.
    pub fn file(&self) -> &File {
        self.temp
            .as_ref()
            .expect("an AtomicFile holds its temp file until commit")
            .as_file()
    }

    /// fsyncs the temp file, renames it over the target and fsyncs the directory.
    pub fn commit(mut self) -> Result<(), PackageError> {
        let temp = self
            .temp
            .take()
            .ok_or_else(|| PackageError::InvalidArgument("atomic file already committed".into()))?;
        let temp_path = temp.path().to_path_buf();
        let r = (|| {
            temp.as_file()
                .sync_all()
                .map_err(|e| PackageError::io("fsync", temp.path(), e))?;
            // On failure the returned error owns the temp file, and dropping it removes it.
            temp.persist(&self.target)
                .map_err(|e| PackageError::io("rename temp file over", &self.target, e.error))?;
            sync_dir(parent_dir(&self.target))
        })();
        unregister(&temp_path);
        r
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.file().write(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.file().flush()
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if let Some(t) = self.temp.take() {
            let p = t.path().to_path_buf();
            drop(t);
            unregister(&p);
        }
    }
}

fn unregister(path: &Path) {
    live().paths.retain(|p| p != path);
}

/// Writes `bytes` to `target` atomically (temp file, fsync, rename, directory fsync).
pub fn write_atomic(target: impl AsRef<Path>, bytes: &[u8]) -> Result<(), PackageError> {
    let mut f = AtomicFile::create(target.as_ref())?;
    f.write_all(bytes)
        .map_err(|e| PackageError::io("write", target.as_ref(), e))?;
    f.commit()
}

/// Makes a rename durable: on POSIX a rename is persisted by fsyncing the directory.
pub(crate) fn sync_dir(dir: &Path) -> Result<(), PackageError> {
    #[cfg(unix)]
    {
        File::open(dir)
            .and_then(|d| d.sync_all())
            .map_err(|e| PackageError::io("fsync directory", dir, e))?;
    }
    #[cfg(not(unix))]
    {
        let _ = (dir, File::open);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temps(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(TEMP_SUFFIX))
            .collect();
        v.sort();
        v
    }

    #[test]
    fn write_atomic_replaces_whole_file_and_leaves_no_temp() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("out.png");
        std::fs::write(&p, b"old contents").unwrap();
        write_atomic(&p, b"new").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"new");
        assert!(temps(dir.path()).is_empty());
    }

    #[test]
    fn dropped_atomic_file_leaves_target_untouched() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("out.aov");
        std::fs::write(&p, b"old").unwrap();
        {
            let mut f = AtomicFile::create(&p).unwrap();
            f.write_all(b"half").unwrap();
            assert_eq!(temps(dir.path()).len(), 1);
        }
        assert_eq!(std::fs::read(&p).unwrap(), b"old");
        assert!(temps(dir.path()).is_empty());
    }

    /// The child half of the next test: run in its own process, since the removal marks the
    /// whole process as exiting.
    #[test]
    fn closing_child() {
        let Some(dir) = std::env::var_os("MOTU_CLOSING_CHILD") else {
            return;
        };
        let dir = PathBuf::from(dir);
        let open = AtomicFile::create(dir.join("a.motu")).unwrap();
        let temp = open.temp_path().unwrap().to_path_buf();
        assert_eq!(remove_registered_temp_files(), 1);
        assert!(!temp.exists());
        let err = AtomicFile::create(dir.join("b.motu")).unwrap_err();
        assert!(err.to_string().contains("exiting on a signal"), "{err}");
        drop(open);
        println!("closing child done");
    }

    /// Regression: an import interrupted just as it opened its partition spill file left that
    /// temp file behind (the signal's removal had already taken the list).
    #[test]
    fn regression_no_temp_file_is_created_after_the_signal_cleanup() {
        let dir = tempfile::tempdir().unwrap();
        let out = std::process::Command::new(std::env::current_exe().unwrap())
            .args(["--exact", "atomic::tests::closing_child", "--nocapture"])
            .env("MOTU_CLOSING_CHILD", dir.path())
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success() && stdout.contains("closing child done"),
            "{stdout}{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(temps(dir.path()).is_empty(), "{:?}", temps(dir.path()));
    }

    #[test]
    fn temp_files_are_registered_while_written() {
        let dir = tempfile::tempdir().unwrap();
        let f = AtomicFile::create(dir.path().join("x.motu")).unwrap();
        let temp = f.temp_path().unwrap().to_path_buf();
        assert!(live().paths.contains(&temp));
        drop(f);
        assert!(!live().paths.contains(&temp) && !temp.exists());
        let f = AtomicFile::create(dir.path().join("y.motu")).unwrap();
        let temp = f.temp_path().unwrap().to_path_buf();
        f.commit().unwrap();
        assert!(!live().paths.contains(&temp));
    }

    #[test]
    fn regression_stale_temp_files_of_dead_processes_are_removed() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("scene.motu");
        // pid 4194305 is above Linux's pid_max: never alive.
        let dead = dir.path().join(".scene.motu.4194305.AbCdEf.motu-tmp");
        let live = dir.path().join(format!(
            ".scene.motu.{}.XyZ123.motu-tmp",
            std::process::id()
        ));
        let other = dir.path().join(".other.motu.4194305.AbCdEf.motu-tmp");
        let old_style = dir.path().join(".scene.motu.AbCdEf.motu-tmp");
        for p in [&dead, &live, &other, &old_style] {
            std::fs::write(p, b"x").unwrap();
        }
        let removed = remove_stale_temp_files(&target).unwrap();
        if process_alive(1).is_none() {
            eprintln!("SKIPPED: no /proc, liveness of temp owners cannot be told");
            return;
        }
        assert_eq!(removed, vec![dead.clone()]);
        assert!(!dead.exists());
        assert!(live.exists() && other.exists() && old_style.exists());
    }
}
