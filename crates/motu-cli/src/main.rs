//! `motu`: import, compile, inspect and render Moana-scale instanced scenes on one GPU.
//! The command line is a contract (`shared/CLI.md`): names and JSON keys are only ever added.
//!
//! # Map
//!
//! (The crate's code map; ARCHITECTURE.md keeps a summary.)
//! The `motu` binary: the contract in `shared/CLI.md`. `cli.rs` (clap arguments), `cmd/` (one file
//! per command: options in, library calls, output), `output.rs` (output checks, all-or-nothing
//! outputs `Outputs`, `OutputDir` for gen, and the input check of command-line paths),
//! `progress.rs`, `signals.rs`; `cmd/bench.rs` maps `motu bench`'s flags onto `motu-bench` (and
//! opens the package and camera for the child render); `cmd/render.rs` checks render's flags, picks
//! the backend and camera, maps the flags onto `motu_render::RenderSettings`, prints each
//! `RenderEvent` and writes the outputs; `cmd/view.rs` checks view's flags, picks the backend and
//! cameras, maps the flags onto `motu_view::PackageSourceSettings` and `ViewOptions`, and writes a
//! scripted run's screenshot, AOV, `--stats` and `--record`.

mod cli;
mod cmd;
mod output;
mod progress;
mod signals;
mod size;

/// The commands' door to the import pipeline (the `motu-import` crate) and to packages.
mod pipeline {
    pub use motu_import::{import, resolve_subset, ImportOptions};

    /// Opens a package with a message that says what to do.
    pub fn open(path: &std::path::Path) -> anyhow::Result<motu_pack::ScenePackage> {
        use anyhow::Context;
        motu_pack::ScenePackage::open(path)
            .with_context(|| format!("opening package {}", path.display()))
    }
}

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    let args = cli::Cli::parse();
    init_tracing(args.verbose);
    signals::install();
    quiet_broken_pipe();
    match cmd::run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", error_paragraph(&e));
            ExitCode::FAILURE
        }
    }
}

/// `motu info … | head`: the reader went away. Rust ignores SIGPIPE, so the next `println!`
/// fails and panics; a Unix tool ends quietly instead (status 141, as if killed by SIGPIPE),
/// removing its unfinished outputs as on SIGINT.
fn quiet_broken_pipe() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let msg = info
            .payload()
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| info.payload().downcast_ref::<&str>().copied())
            .unwrap_or("");
        if msg.starts_with("failed printing to stdout") && msg.contains("Broken pipe") {
            let _ = motu_package::atomic::remove_registered_temp_outputs();
            std::process::exit(141);
        }
        default(info)
    }));
}

/// One paragraph: what, where, what to do (the contexts carry the where). Library errors often
/// print their source in their own message too; a cause already shown is not repeated.
fn error_paragraph(e: &anyhow::Error) -> String {
    terminal_safe(&error_text(e))
}

/// `text` with control characters from input files (escape sequences, bells, NULs) shown as
/// `\x1b`, never sent to the terminal as they are; line breaks and tabs are kept.
pub(crate) fn terminal_safe(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        if c.is_control() && c != '\n' && c != '\t' {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
    }
    out
}

fn error_text(e: &anyhow::Error) -> String {
    let mut msg = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if msg.contains(&text) {
            continue;
        }
        if !msg.is_empty() {
            msg.push_str(": ");
        }
        msg.push_str(&text);
    }
    msg
}

fn init_tracing(verbose: u8) {
    use tracing_subscriber::EnvFilter;
    let default = match verbose {
        0 => "warn",
        1 => "info",
        2 => "debug",
        _ => "trace",
    };
    // winit's Wayland title bar (sctk-adwaita) logs an ERROR when no XDG settings portal
    // answers, which desktops without one never do: noise, not a motu problem.
    let fallback = || EnvFilter::new(format!("{default},sctk_adwaita=off"));
    let (filter, bad) = match std::env::var("MOTU_LOG") {
        Ok(v) => match EnvFilter::try_new(&v) {
            Ok(f) => (f, None),
            Err(e) => (fallback(), Some(format!("{v:?} ({e})"))),
        },
        Err(_) => (fallback(), None),
    };
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        // Colour codes only for a person at a terminal, never in logs or captured output.
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .init();
    if let Some(bad) = bad {
        // Said, not silently replaced: the user asked for logs they would not get.
        eprintln!(
            "warning: MOTU_LOG={bad} is not a log filter (e.g. `info`, `motu_gpu=debug`); logging at `{default}`"
        );
    }
}

#[cfg(test)]
mod tests;
