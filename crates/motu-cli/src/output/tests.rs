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
    let e =
        check_outputs(&[], &[("-o", &x), ("--stats", &dotted.with_file_name("x"))]).unwrap_err();
    assert!(e.to_string().contains("same file"), "{e}");
    // Distinct outputs pass.
    check_outputs(
        &[("package", &input)],
        &[("-o", &dir.path().join("a.png")), ("--aov", &x)],
    )
    .unwrap();
}

fn temps(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".motu-tmp"))
        .collect()
}

/// Issue 49: `render -o out.png --aov <unwritable>` replaced out.png, then failed.
#[test]
fn regression_outputs_are_all_or_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("out.png");
    let aov = dir.path().join("out.aov");
    std::fs::write(&png, b"old png").unwrap();
    std::fs::write(&aov, b"old aov").unwrap();
    // An output that cannot be written (procfs refuses new files, even to root) fails
    // before any work, leaving every target and no temp file.
    let e = Outputs::begin(&[], &[("-o", &png), ("--aov", Path::new("/proc/motu.aov"))])
        .err()
        .unwrap();
    assert!(e.to_string().contains("--aov /proc/motu.aov"), "{e:#}");
    assert_eq!(std::fs::read(&png).unwrap(), b"old png");
    assert!(temps(dir.path()).is_empty(), "{:?}", temps(dir.path()));
    // Written but not committed (the second write failed, a full disk): both old.
    {
        let mut outs = Outputs::begin(&[], &[("-o", &png), ("--aov", &aov)]).unwrap();
        outs.write(&png, b"new png").unwrap();
    }
    assert_eq!(std::fs::read(&png).unwrap(), b"old png");
    assert_eq!(std::fs::read(&aov).unwrap(), b"old aov");
    assert!(temps(dir.path()).is_empty(), "{:?}", temps(dir.path()));
    // Committed: both new.
    let mut outs = Outputs::begin(&[], &[("-o", &png), ("--aov", &aov)]).unwrap();
    outs.write(&png, b"new png").unwrap();
    outs.write(&aov, b"new aov").unwrap();
    outs.commit().unwrap();
    assert_eq!(std::fs::read(&png).unwrap(), b"new png");
    assert_eq!(std::fs::read(&aov).unwrap(), b"new aov");
    assert!(temps(dir.path()).is_empty(), "{:?}", temps(dir.path()));
}

/// A render commits its image before persisting its structure cache (`commit_some`); a
/// failure after that (its `--stats` unwritten) must still leave every target as it was.
#[test]
fn outputs_committed_early_are_put_back_when_the_command_fails() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("out.png");
    let fresh = dir.path().join("new.aov");
    let stats = dir.path().join("stats.json");
    std::fs::write(&png, b"old png").unwrap();
    {
        let mut outs =
            Outputs::begin(&[], &[("-o", &png), ("--aov", &fresh), ("--stats", &stats)]).unwrap();
        outs.write(&png, b"new png").unwrap();
        outs.write(&fresh, b"new aov").unwrap();
        assert!(outs.commit_some(&[&png, &fresh]).unwrap());
        // Visible at once, the old contents kept aside.
        assert_eq!(std::fs::read(&png).unwrap(), b"new png");
        assert_eq!(std::fs::read(&fresh).unwrap(), b"new aov");
        // Dropped before the final commit: the stats were never written.
    }
    assert_eq!(std::fs::read(&png).unwrap(), b"old png");
    assert!(
        !fresh.exists(),
        "an output that did not exist before is removed"
    );
    assert!(!stats.exists());
    assert!(temps(dir.path()).is_empty(), "{:?}", temps(dir.path()));
    // Committed in full: every output new, no old copy left behind.
    let mut outs =
        Outputs::begin(&[], &[("-o", &png), ("--aov", &fresh), ("--stats", &stats)]).unwrap();
    outs.write(&png, b"new png").unwrap();
    outs.write(&fresh, b"new aov").unwrap();
    assert!(outs.commit_some(&[&png, &fresh]).unwrap());
    outs.write(&stats, b"{}").unwrap();
    outs.commit().unwrap();
    assert_eq!(std::fs::read(&png).unwrap(), b"new png");
    assert_eq!(std::fs::read(&stats).unwrap(), b"{}");
    assert!(temps(dir.path()).is_empty(), "{:?}", temps(dir.path()));
}

#[test]
fn regression_output_dir_refuses_non_empty_without_replace() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scene");
    std::fs::create_dir(&scene).unwrap();
    std::fs::write(scene.join("keep.pbrt"), b"mine").unwrap();
    let e = OutputDir::begin("-o", &scene, false).err().unwrap();
    assert!(
        e.to_string().contains("not empty") && e.to_string().contains("--force"),
        "{e}"
    );
    let out = OutputDir::begin("-o", &scene, true).unwrap();
    std::fs::write(out.path().join("scene.pbrt"), b"new").unwrap();
    out.commit("scene.pbrt").unwrap();
    assert!(!scene.join("keep.pbrt").exists());
    assert_eq!(std::fs::read(scene.join("scene.pbrt")).unwrap(), b"new");
    let file = dir.path().join("file");
    std::fs::write(&file, b"x").unwrap();
    let e = OutputDir::begin("-o", &file, true).err().unwrap();
    assert!(e.to_string().contains("not a directory"), "{e}");
    assert!(temps(dir.path()).is_empty(), "{:?}", temps(dir.path()));
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
