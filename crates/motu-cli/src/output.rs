//! Output files: checked before any work (never an input of the same command, never another
//! output of it, never a non-regular file, in a directory that exists and can be written),
//! then written through one atomic path (temp file, fsync, rename: `motu_package::atomic`);
//! a command's several outputs are all or nothing ([`Outputs`]). And the one check for input
//! paths given on the command line ([`check_input`]).

use anyhow::{bail, Context};
use motu_package::identity::{describe_file_type, FileIdentity};
use std::path::Path;

/// Identity of an output path; errors when it is not a plain file or its directory is missing.
fn output_identity(option: &str, path: &Path) -> anyhow::Result<FileIdentity> {
    match std::fs::symlink_metadata(path) {
        Ok(m) if m.file_type().is_file() => Ok(FileIdentity::of(&m)),
        Ok(m) => bail!(
            "{option} {}: exists and is {}, not a regular file; motu only replaces regular files (remove it or choose another path)",
            path.display(),
            describe_file_type(&m.file_type())
        ),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            let dir = motu_package::atomic::parent_dir(path);
            let name = path
                .file_name()
                .with_context(|| format!("{option} {}: names no file", path.display()))?;
            match std::fs::metadata(dir) {
                Ok(d) if d.is_dir() => {}
                Ok(_) => bail!(
                    "{option} {}: {} is not a directory",
                    path.display(),
                    dir.display()
                ),
                Err(_) => bail!(
                    "{option} {}: the directory {} does not exist (create it first)",
                    path.display(),
                    dir.display()
                ),
            }
            let dir = dir
                .canonicalize()
                .with_context(|| format!("{option} {}: resolving its directory", path.display()))?;
            Ok(FileIdentity::New(dir.join(name)))
        }
        Err(e) => Err(e).with_context(|| format!("{option} {}", path.display())),
    }
}

/// Refuses outputs that are inputs of the same command, repeat another output, exist as
/// anything but a regular file, or lie in a directory that does not exist. Run before work.
/// `inputs` and `outputs` pair an option name (`-o`, `--aov`, `package`) with a path.
pub fn check_outputs(inputs: &[(&str, &Path)], outputs: &[(&str, &Path)]) -> anyhow::Result<()> {
    let ins: Vec<(&str, &Path, FileIdentity)> = inputs
        .iter()
        .filter_map(|&(o, p)| FileIdentity::of_input(p).map(|id| (o, p, id)))
        .collect();
    let mut outs: Vec<(&str, &Path, FileIdentity)> = Vec::new();
    for &(option, path) in outputs {
        let id = output_identity(option, path)?;
        if let Some((io, ip, _)) = ins.iter().find(|(_, _, i)| *i == id) {
            bail!(
                "{option} {} is the {io} {}: an output never replaces an input (choose another path)",
                path.display(),
                ip.display()
            );
        }
        if let Some((oo, op, _)) = outs.iter().find(|(_, _, i)| *i == id) {
            bail!(
                "{option} {} and {oo} {} are the same file: each output needs its own path",
                path.display(),
                op.display()
            );
        }
        outs.push((option, path, id));
    }
    Ok(())
}

/// A command's outputs, all or nothing: checked (as [`check_outputs`]) and their temp files
/// created before any work, so an unwritable directory fails before the work and before any
/// target is touched; written into the temp files; renamed into place only when every one is
/// written and fsynced ([`commit`](Self::commit); a group of them may go first,
/// [`commit_some`](Self::commit_some), their old contents kept until then). Dropped
/// uncommitted (an error, a full disk), every temp file is removed and every target keeps (or
/// gets back) its old contents.
pub struct Outputs {
    files: Vec<(String, std::path::PathBuf, motu_package::atomic::AtomicFile)>,
    /// Outputs renamed into place early ([`commit_some`](Self::commit_some)), each with a hard
    /// link to the target's old contents (`None`: there was none), put back if the command
    /// fails before [`commit`](Self::commit): all or nothing still holds.
    early: Vec<(std::path::PathBuf, Option<std::path::PathBuf>)>,
}

impl Outputs {
    /// Checks `outputs` against `inputs` and each other, then creates each one's temp file.
    pub fn begin(inputs: &[(&str, &Path)], outputs: &[(&str, &Path)]) -> anyhow::Result<Self> {
        check_outputs(inputs, outputs)?;
        let mut files = Vec::with_capacity(outputs.len());
        for &(option, path) in outputs {
            let f = motu_package::atomic::AtomicFile::create(path).with_context(|| {
                format!(
                    "{option} {}: cannot be written (checked before any work)",
                    path.display()
                )
            })?;
            files.push((option.to_string(), path.to_path_buf(), f));
        }
        Ok(Outputs {
            files,
            early: Vec::new(),
        })
    }

    /// Writes the whole contents of the output `path` (one of those given to `begin`).
    pub fn write(&mut self, path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
        use std::io::Write;
        let (option, _, f) = self
            .files
            .iter_mut()
            .find(|(_, p, _)| p == path)
            .with_context(|| format!("{} is not an output of this command", path.display()))?;
        f.write_all(bytes)
            .and_then(|()| f.file().sync_all())
            .with_context(|| format!("writing {option} {}", path.display()))
    }

    /// Encodes an RGBA8 image as PNG into the output `path`.
    pub fn write_png(
        &mut self,
        path: &Path,
        width: u32,
        height: u32,
        rgba8: &[u8],
    ) -> anyhow::Result<()> {
        let png = motu_trace::encode_png(width, height, rgba8)
            .with_context(|| format!("encoding {}", path.display()))?;
        self.write(path, &png)
    }

    /// Renames the outputs `paths` into place now (each written and fsynced by `write`), the
    /// others staying for [`commit`](Self::commit): a render's image before its slower
    /// bookkeeping. Each target's old contents are kept as a hard link beside it until the
    /// final commit, and put back if the command fails before it (the drop). Returns false,
    /// renaming nothing, where such a link cannot be made (the final commit renames them).
    pub fn commit_some(&mut self, paths: &[&Path]) -> anyhow::Result<bool> {
        let mut backups = Vec::new();
        for &path in paths {
            match backup_of(path) {
                Ok(b) => backups.push((path.to_path_buf(), b)),
                Err(e) => {
                    tracing::debug!(path = %path.display(), %e, "no early commit: cannot keep the old file");
                    for (_, b) in backups {
                        if let Some(b) = b {
                            let _ = std::fs::remove_file(b);
                        }
                    }
                    return Ok(false);
                }
            }
        }
        let (now, rest): (Vec<_>, Vec<_>) = std::mem::take(&mut self.files)
            .into_iter()
            .partition(|(_, p, _)| paths.contains(&p.as_path()));
        self.files = rest;
        // Recorded before the renames: a failure puts back whatever was renamed.
        self.early.extend(backups);
        for (option, path, f) in now {
            f.commit()
                .with_context(|| format!("writing {option} {}", path.display()))?;
        }
        Ok(true)
    }

    /// Renames every output into place (each was written and fsynced by `write`).
    pub fn commit(mut self) -> anyhow::Result<()> {
        for (option, path, f) in std::mem::take(&mut self.files) {
            f.commit()
                .with_context(|| format!("writing {option} {}", path.display()))?;
        }
        for (_, backup) in std::mem::take(&mut self.early) {
            if let Some(b) = backup {
                let _ = std::fs::remove_file(b);
            }
        }
        Ok(())
    }
}

impl Drop for Outputs {
    /// Uncommitted: the outputs renamed early get their old contents back (or are removed
    /// where there were none); the temp files of the others are removed by their own drops.
    fn drop(&mut self) {
        for (path, backup) in std::mem::take(&mut self.early) {
            let r = match &backup {
                Some(b) => std::fs::rename(b, &path),
                None => std::fs::remove_file(&path),
            };
            if let Err(e) = r {
                eprintln!(
                    "warning: {}: could not restore its old contents: {e}",
                    path.display()
                );
            }
        }
    }
}

/// A hard link to `target`'s current contents beside it, named as a motu temp file of this
/// process (`.NAME.PID.oldN.motu-tmp`: a later write removes it if this process dies), or
/// `None` where the target does not exist.
fn backup_of(target: &Path) -> std::io::Result<Option<std::path::PathBuf>> {
    match std::fs::symlink_metadata(target) {
        Ok(m) if m.is_file() => {}
        Ok(_) => {
            return Err(std::io::Error::other("not a regular file"));
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(e),
    }
    let name = target
        .file_name()
        .ok_or_else(|| std::io::Error::other("no file name"))?
        .to_string_lossy()
        .into_owned();
    let dir = motu_package::atomic::parent_dir(target);
    for n in 0..64 {
        let b = dir.join(format!(
            ".{name}.{}.old{n}{}",
            std::process::id(),
            motu_package::atomic::TEMP_SUFFIX
        ));
        match std::fs::hard_link(target, &b) {
            Ok(()) => return Ok(Some(b)),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e),
        }
    }
    Err(std::io::Error::other("no free backup name"))
}

/// An output directory written whole (`motu gen`): checked before any work (not a file, a
/// symlink or a device; empty, missing, or replaced only with `replace`), written into a temp
/// directory beside it, and renamed into place by [`commit`](Self::commit). Dropped
/// uncommitted (a bad option found while writing, a full disk), it leaves nothing behind.
pub struct OutputDir {
    dir: motu_package::atomic::AtomicDir,
}

impl OutputDir {
    pub fn begin(option: &str, path: &Path, replace: bool) -> anyhow::Result<Self> {
        match std::fs::symlink_metadata(path) {
            Ok(m) if m.is_dir() => {
                let mut entries = std::fs::read_dir(path)
                    .with_context(|| format!("{option} {}: reading it", path.display()))?;
                if entries.next().is_some() && !replace {
                    bail!(
                        "{option} {}: the directory is not empty; give --force to replace it as a whole, or choose another path",
                        path.display()
                    );
                }
            }
            Ok(m) => bail!(
                "{option} {}: exists and is {}, not a directory (remove it or choose another path)",
                path.display(),
                describe_file_type(&m.file_type())
            ),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                let parent = motu_package::atomic::parent_dir(path);
                if !parent.is_dir() {
                    bail!(
                        "{option} {}: the directory {} does not exist (create it first)",
                        path.display(),
                        parent.display()
                    );
                }
            }
            Err(e) => return Err(e).with_context(|| format!("{option} {}", path.display())),
        }
        let dir = motu_package::atomic::AtomicDir::create(path).with_context(|| {
            format!(
                "{option} {}: cannot be written (checked before any work)",
                path.display()
            )
        })?;
        Ok(OutputDir { dir })
    }

    /// The temp directory to write into.
    pub fn path(&self) -> &Path {
        self.dir.path()
    }

    /// Renames the written directory into place (`last`, the entry file, appears last where
    /// the directory's entries are replaced one by one: `-o .`).
    pub fn commit(self, last: &str) -> anyhow::Result<()> {
        let target = self.dir.target_display();
        self.dir
            .commit_last(last)
            .with_context(|| format!("writing {target}"))
    }
}

/// The input check every path given on the command line passes before it is opened
/// (`motu_package::identity::check_input`): a regular file, of at most `max_bytes` when given.
pub fn check_input(option: &str, path: &Path, max_bytes: Option<u64>) -> anyhow::Result<u64> {
    motu_package::identity::check_input(path, max_bytes)
        .with_context(|| format!("{option} {}", path.display()))
}

#[cfg(test)]
mod tests;
