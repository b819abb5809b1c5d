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
    /// Temp directories (`AtomicDir`), removed with their contents.
    dirs: Vec<PathBuf>,
    /// Targets renamed into place by this process, for the signal message: an interrupt that
    /// comes after an output was completed says so instead of "removed 0".
    committed: Vec<PathBuf>,
    closing: bool,
}

static LIVE: Mutex<Live> = Mutex::new(Live {
    paths: Vec::new(),
    dirs: Vec::new(),
    committed: Vec::new(),
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
    remove_registered_temp_outputs().removed
}

/// What [`remove_registered_temp_outputs`] did.
#[derive(Debug, Default)]
pub struct SignalCleanup {
    /// Temp files and directories removed (unfinished outputs).
    pub removed: usize,
    /// Targets this process had already completed (renamed into place) before the signal.
    pub completed: Vec<PathBuf>,
}

/// [`remove_registered_temp_files`], also saying which outputs were already complete. A
/// commit and this removal exclude each other (one lock): an output is either renamed into
/// place before it (listed in `completed`) or never (its temp file removed, the target kept).
pub fn remove_registered_temp_outputs() -> SignalCleanup {
    let (paths, dirs, completed) = {
        let mut l = live();
        l.closing = true;
        (
            std::mem::take(&mut l.paths),
            std::mem::take(&mut l.dirs),
            l.committed.clone(),
        )
    };
    let files = paths
        .iter()
        .filter(|p| std::fs::remove_file(p).is_ok())
        .count();
    let dirs = dirs
        .iter()
        .filter(|d| std::fs::remove_dir_all(d).is_ok())
        .count();
    SignalCleanup {
        removed: files + dirs,
        completed,
    }
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
        let Ok(t) = e.file_type() else { continue };
        let gone = if t.is_file() {
            std::fs::remove_file(e.path()).is_ok()
        } else {
            // An `AtomicDir` of a dead process (symlinks are never followed or removed).
            t.is_dir() && std::fs::remove_dir_all(e.path()).is_ok()
        };
        if gone {
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
            {
                // The rename and the signal cleanup exclude each other: after a signal nothing
                // is renamed into place (the interrupt wins, the target keeps its old
                // contents); a rename done first is recorded as completed for its message.
                let mut l = live();
                if l.closing {
                    let e = std::io::Error::new(
                        std::io::ErrorKind::Interrupted,
                        "the process is exiting on a signal",
                    );
                    return Err(PackageError::io("rename temp file over", &self.target, e));
                }
                // On failure the returned error owns the temp file, and dropping it removes it.
                temp.persist(&self.target).map_err(|e| {
                    PackageError::io("rename temp file over", &self.target, e.error)
                })?;
                l.paths.retain(|p| p != &temp_path);
                l.committed.push(self.target.clone());
            }
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

/// A directory written beside `target` (`.NAME.PID.RANDOM.motu-tmp/`) and renamed into place by
/// [`commit`](Self::commit): the target is its old self or complete, never half-written.
/// Dropped uncommitted, the temp directory and everything in it is removed; a signal removes
/// it too ([`remove_registered_temp_files`]).
#[derive(Debug)]
pub struct AtomicDir {
    target: PathBuf,
    temp: Option<PathBuf>,
}

impl AtomicDir {
    /// Creates the temp directory beside `target` (removing stale temp files of `target`).
    pub fn create(target: impl AsRef<Path>) -> Result<Self, PackageError> {
        let mut target = target.as_ref().to_path_buf();
        if target.file_name().is_none() {
            // `.` or `..`: the directory it names, by its own name.
            target = target
                .canonicalize()
                .map_err(|e| PackageError::io("resolve", &target, e))?;
        }
        let prefix = format!("{}{}.", temp_prefix(&target)?, std::process::id());
        let _ = remove_stale_temp_files(&target);
        let mut l = live();
        if l.closing {
            let e = std::io::Error::new(
                std::io::ErrorKind::Interrupted,
                "the process is exiting on a signal",
            );
            return Err(PackageError::io("create temp directory beside", &target, e));
        }
        let temp = tempfile::Builder::new()
            .prefix(&prefix)
            .suffix(TEMP_SUFFIX)
            .tempdir_in(parent_dir(&target))
            .map_err(|e| PackageError::io("create temp directory beside", &target, e))?
            .keep();
        l.dirs.push(temp.clone());
        drop(l);
        Ok(AtomicDir {
            target,
            temp: Some(temp),
        })
    }

    /// The target, for messages.
    pub fn target_display(&self) -> String {
        self.target.display().to_string()
    }

    /// The temp directory to write into.
    pub fn path(&self) -> &Path {
        self.temp
            .as_deref()
            .expect("an AtomicDir holds its temp directory until commit")
    }

    /// fsyncs every file written, then renames the directory into place. An existing target
    /// directory is replaced as a whole (moved aside, the new one renamed in, the old one
    /// removed); an existing target that is not a directory is refused. The working directory
    /// (or one above it) keeps its inode: its entries are replaced, the entry named `last`
    /// (such as `scene.pbrt`) renamed after every other.
    pub fn commit(self) -> Result<(), PackageError> {
        self.commit_last("")
    }

    /// [`commit`](Self::commit) naming the entry renamed last when entries are replaced.
    pub fn commit_last(mut self, last: &str) -> Result<(), PackageError> {
        let temp = self
            .temp
            .clone()
            .ok_or_else(|| PackageError::InvalidArgument("atomic dir already committed".into()))?;
        sync_tree(&temp)?;
        let mut l = live();
        if l.closing {
            let e = std::io::Error::new(
                std::io::ErrorKind::Interrupted,
                "the process is exiting on a signal",
            );
            return Err(PackageError::io(
                "rename temp directory to",
                &self.target,
                e,
            ));
        }
        if holds_current_dir(&self.target) {
            // Renaming over the working directory would leave this shell in a deleted one:
            // its entries are replaced instead, `last` renamed last (an entry file appears
            // only once everything it names is in place).
            drop(l);
            let r = replace_entries(&temp, &self.target, last);
            if r.is_ok() {
                let _ = std::fs::remove_dir_all(&temp);
                let mut l = live();
                l.dirs.retain(|d| d != &temp);
                l.committed.push(self.target.clone());
                self.temp = None;
            }
            return r.and_then(|()| sync_dir(&self.target));
        }
        let old = match std::fs::symlink_metadata(&self.target) {
            Ok(m) if m.is_dir() => {
                // Moved aside under a temp name of this process: removed below, or by a later
                // write to the same target if this process dies before that.
                // `.NAME.PID.RANDOMold.motu-tmp`: still a temp name of this process.
                let name = temp.file_name().map_or_else(String::new, |n| {
                    n.to_string_lossy()
                        .trim_end_matches(TEMP_SUFFIX)
                        .to_string()
                });
                let old = temp.with_file_name(format!("{name}old{TEMP_SUFFIX}"));
                std::fs::rename(&self.target, &old).map_err(|e| {
                    PackageError::io("move aside the old directory", &self.target, e)
                })?;
                l.dirs.push(old.clone());
                Some(old)
            }
            Ok(_) => {
                return Err(PackageError::io(
                    "replace",
                    &self.target,
                    std::io::Error::new(
                        std::io::ErrorKind::AlreadyExists,
                        "exists and is not a directory",
                    ),
                ))
            }
            Err(_) => None,
        };
        if let Err(e) = std::fs::rename(&temp, &self.target) {
            if let Some(old) = &old {
                let _ = std::fs::rename(old, &self.target);
                l.dirs.retain(|d| d != old);
            }
            return Err(PackageError::io(
                "rename temp directory to",
                &self.target,
                e,
            ));
        }
        l.dirs.retain(|d| d != &temp);
        l.committed.push(self.target.clone());
        self.temp = None;
        drop(l);
        if let Some(old) = old {
            let _ = std::fs::remove_dir_all(&old);
            live().dirs.retain(|d| d != &old);
        }
        sync_dir(parent_dir(&self.target))
    }
}

impl Drop for AtomicDir {
    fn drop(&mut self) {
        if let Some(t) = self.temp.take() {
            let _ = std::fs::remove_dir_all(&t);
            live().dirs.retain(|d| d != &t);
        }
    }
}

/// Whether `dir` is the working directory or one above it.
fn holds_current_dir(dir: &Path) -> bool {
    match (std::env::current_dir(), dir.canonicalize()) {
        (Ok(cwd), Ok(dir)) => cwd.starts_with(dir),
        _ => false,
    }
}

/// Replaces `target`'s entries by `from`'s: the old ones removed (the caller checked the
/// target was empty or may be replaced), the new ones renamed in, `last` after the others.
fn replace_entries(from: &Path, target: &Path, last: &str) -> Result<(), PackageError> {
    let list = |dir: &Path| -> Result<Vec<std::fs::DirEntry>, PackageError> {
        std::fs::read_dir(dir)
            .and_then(|it| it.collect::<std::io::Result<Vec<_>>>())
            .map_err(|e| PackageError::io("read", dir, e))
    };
    // The old entry file first, so no reader meets it beside half-replaced files.
    let mut old = list(target)?;
    old.sort_by_key(|e| e.file_name() != last);
    for e in old {
        let p = e.path();
        let r = if e.file_type().is_ok_and(|t| t.is_dir()) {
            std::fs::remove_dir_all(&p)
        } else {
            std::fs::remove_file(&p)
        };
        r.map_err(|err| PackageError::io("remove", &p, err))?;
    }
    let mut new = list(from)?;
    new.sort_by_key(|e| e.file_name() == last);
    for e in new {
        let to = target.join(e.file_name());
        std::fs::rename(e.path(), &to).map_err(|err| PackageError::io("rename into", &to, err))?;
    }
    Ok(())
}

/// fsyncs every regular file and directory under `dir` (before a rename makes them visible).
fn sync_tree(dir: &Path) -> Result<(), PackageError> {
    let entries = std::fs::read_dir(dir).map_err(|e| PackageError::io("read", dir, e))?;
    for e in entries {
        let e = e.map_err(|err| PackageError::io("read", dir, err))?;
        let t = e
            .file_type()
            .map_err(|err| PackageError::io("stat", e.path(), err))?;
        if t.is_dir() {
            sync_tree(&e.path())?;
        } else if t.is_file() {
            File::open(e.path())
                .and_then(|f| f.sync_all())
                .map_err(|err| PackageError::io("fsync", e.path(), err))?;
        }
    }
    sync_dir(dir)
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
mod tests;
