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
    let done = dir.join("done.motu");
    AtomicFile::create(&done).unwrap().commit().unwrap();
    let late = dir.join("late.motu");
    std::fs::write(&late, b"old").unwrap();
    let mut pending = AtomicFile::create(&late).unwrap();
    pending.write_all(b"new").unwrap();
    let gen_dir = AtomicDir::create(dir.join("scene")).unwrap();
    std::fs::write(gen_dir.path().join("scene.pbrt"), b"x").unwrap();
    let cleanup = remove_registered_temp_outputs();
    assert_eq!(cleanup.removed, 3);
    assert_eq!(cleanup.completed, vec![done]);
    assert!(!temp.exists());
    let err = AtomicFile::create(dir.join("b.motu")).unwrap_err();
    assert!(err.to_string().contains("exiting on a signal"), "{err}");
    // The interrupt wins over a commit after it: the old target is kept.
    assert!(pending.commit().is_err());
    assert_eq!(std::fs::read(&late).unwrap(), b"old");
    assert!(gen_dir.commit().is_err());
    assert!(!dir.join("scene").exists());
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
fn regression_atomic_dir_replaces_whole_or_not_at_all() {
    let dir = tempfile::tempdir().unwrap();
    let target = dir.path().join("scene");
    // Dropped uncommitted: nothing left, not even an empty target.
    {
        let d = AtomicDir::create(&target).unwrap();
        std::fs::write(d.path().join("scene.pbrt"), b"half").unwrap();
    }
    assert!(!target.exists());
    assert!(temps(dir.path()).is_empty(), "{:?}", temps(dir.path()));
    let d = AtomicDir::create(&target).unwrap();
    std::fs::create_dir(d.path().join("geometry")).unwrap();
    std::fs::write(d.path().join("geometry/a.ply"), b"a").unwrap();
    std::fs::write(d.path().join("scene.pbrt"), b"one").unwrap();
    d.commit().unwrap();
    assert_eq!(std::fs::read(target.join("scene.pbrt")).unwrap(), b"one");
    // A second commit replaces the directory as a whole: no file of the old one stays.
    let d = AtomicDir::create(&target).unwrap();
    std::fs::write(d.path().join("scene.pbrt"), b"two").unwrap();
    d.commit().unwrap();
    assert_eq!(std::fs::read(target.join("scene.pbrt")).unwrap(), b"two");
    assert!(!target.join("geometry").exists());
    assert!(temps(dir.path()).is_empty(), "{:?}", temps(dir.path()));
    // A file where the directory should go is refused and kept.
    let file = dir.path().join("file");
    std::fs::write(&file, b"keep").unwrap();
    let d = AtomicDir::create(&file).unwrap();
    assert!(d.commit().is_err());
    assert_eq!(std::fs::read(&file).unwrap(), b"keep");
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
