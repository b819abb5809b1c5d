//! Output files: checked before any work (never an input of the same command, never another
//! output of it, never a non-regular file, in a directory that exists), then written through
//! one atomic path (temp file, fsync, rename: `motu_package::atomic`).

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

/// Writes `bytes` to `path` atomically.
pub fn write(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    motu_package::atomic::write_atomic(path, bytes)
        .with_context(|| format!("writing {}", path.display()))
}

/// Encodes an RGBA8 image as PNG and writes it atomically.
pub fn write_png(path: &Path, width: u32, height: u32, rgba8: &[u8]) -> anyhow::Result<()> {
    let png = motu_trace::encode_png(width, height, rgba8)
        .with_context(|| format!("encoding {}", path.display()))?;
    write(path, &png)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regression_output_equal_to_input_or_other_output_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("p.motu");
        std::fs::write(&input, b"pkg").unwrap();
        let e = check_outputs(&[("package", &input)], &[("-o", &input)]).unwrap_err();
        assert!(e.to_string().contains("never replaces an input"), "{e}");
        // The same file by another spelling and by a hard link.
        let dotted = dir.path().join(".").join("p.motu");
        assert!(check_outputs(&[("package", &input)], &[("-o", &dotted)]).is_err());
        let link = dir.path().join("hard.motu");
        std::fs::hard_link(&input, &link).unwrap();
        assert!(check_outputs(&[("package", &input)], &[("--aov", &link)]).is_err());
        // Two outputs naming one new file.
        let x = dir.path().join("x");
        let e = check_outputs(&[], &[("-o", &x), ("--stats", &dotted.with_file_name("x"))])
            .unwrap_err();
        assert!(e.to_string().contains("same file"), "{e}");
        // Distinct outputs pass.
        check_outputs(
            &[("package", &input)],
            &[("-o", &dir.path().join("a.png")), ("--aov", &x)],
        )
        .unwrap();
    }

    #[test]
    fn regression_non_regular_outputs_and_missing_dirs_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("t.png");
        std::fs::write(&target, b"x").unwrap();
        let link = dir.path().join("link.png");
        std::os::unix::fs::symlink(&target, &link).unwrap();
        let e = check_outputs(&[], &[("-o", &link)]).unwrap_err();
        assert!(e.to_string().contains("symbolic link"), "{e}");
        let e = check_outputs(&[], &[("-o", Path::new("/dev/null"))]).unwrap_err();
        assert!(e.to_string().contains("character device"), "{e}");
        let e = check_outputs(&[], &[("-o", dir.path())]).unwrap_err();
        assert!(e.to_string().contains("a directory"), "{e}");
        let e = check_outputs(&[], &[("--html", &dir.path().join("no/such/r.html"))]).unwrap_err();
        assert!(e.to_string().contains("does not exist"), "{e}");
    }
}
