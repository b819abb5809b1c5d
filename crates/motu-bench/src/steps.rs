//! Child processes: one step (gen, import, render) of a suite, run, logged, timed out.

use serde_json::Value;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// How one child process ended.
#[derive(Debug)]
pub(crate) struct StepRun {
    pub(crate) wall_s: f64,
    pub(crate) stdout: String,
    /// `None` on success; else what went wrong (the child's error paragraph, a signal, a timeout).
    pub(crate) error: Option<String>,
}

/// Runs this executable with `args`, logging its output under `log_dir/<tag>.{out,err}`.
pub(crate) fn run_step(args: &[String], log_dir: &Path, tag: &str, timeout: Duration) -> StepRun {
    let t0 = Instant::now();
    let fail = |e: String| StepRun {
        wall_s: t0.elapsed().as_secs_f64(),
        stdout: String::new(),
        error: Some(e),
    };
    let exe = match std::env::current_exe() {
        Ok(e) => e,
        Err(e) => return fail(format!("cannot find the motu executable: {e}")),
    };
    let out_path = log_dir.join(format!("{tag}.out"));
    let err_path = log_dir.join(format!("{tag}.err"));
    let (out_file, err_file) = match (
        std::fs::File::create(&out_path),
        std::fs::File::create(&err_path),
    ) {
        (Ok(o), Ok(e)) => (o, e),
        (Err(e), _) | (_, Err(e)) => {
            return fail(format!("cannot create logs in {}: {e}", log_dir.display()))
        }
    };
    let mut child = match Command::new(&exe)
        .args(args)
        .stdin(Stdio::null())
        .stdout(out_file)
        .stderr(err_file)
        .spawn()
    {
        Ok(c) => c,
        Err(e) => return fail(format!("cannot start {}: {e}", exe.display())),
    };
    let mut timed_out = false;
    let status = loop {
        match child.try_wait() {
            Ok(Some(st)) => break Some(st),
            Ok(None) if t0.elapsed() > timeout => {
                timed_out = true;
                // Killing our own child by its handle; a failure means it already exited.
                let _ = child.kill();
                break child.wait().ok();
            }
            Ok(None) => std::thread::sleep(Duration::from_millis(20)),
            Err(e) => return fail(format!("waiting for the child process: {e}")),
        }
    };
    let wall_s = t0.elapsed().as_secs_f64();
    let stdout = std::fs::read_to_string(&out_path).unwrap_or_default();
    let stderr = std::fs::read_to_string(&err_path).unwrap_or_default();
    let error = if timed_out {
        Some(format!(
            "timed out after {} s (--step-timeout-s); log: {}",
            timeout.as_secs(),
            err_path.display()
        ))
    } else {
        match status {
            Some(st) if st.success() => None,
            Some(st) => Some(child_error(&stderr, st, &err_path)),
            None => Some("the child process vanished".into()),
        }
    };
    StepRun {
        wall_s,
        stdout,
        error,
    }
}

/// The child's own error paragraph, else how it ended.
fn child_error(stderr: &str, status: std::process::ExitStatus, log: &Path) -> String {
    use std::os::unix::process::ExitStatusExt;
    let line = stderr
        .lines()
        .rev()
        .find(|l| l.starts_with("error"))
        .or_else(|| stderr.lines().rev().find(|l| !l.trim().is_empty()))
        .unwrap_or("")
        .trim();
    let how = match (status.code(), status.signal()) {
        (Some(c), _) => format!("exit status {c}"),
        (None, Some(9)) => "killed (signal 9: out of memory?)".to_string(),
        (None, Some(s)) => format!("killed by signal {s}"),
        (None, None) => "ended abnormally".to_string(),
    };
    let mut msg = if line.is_empty() {
        how
    } else {
        format!("{line} ({how})")
    };
    if msg.len() > 600 {
        let mut cut = 600;
        while !msg.is_char_boundary(cut) {
            cut -= 1;
        }
        msg.truncate(cut);
        msg.push('…');
    }
    format!("{msg}; log: {}", log.display())
}

pub(crate) fn parse_json(stdout: &str) -> Result<Value, String> {
    serde_json::from_str(stdout.trim()).map_err(|e| format!("the child printed no JSON ({e})"))
}
