//! One module per subcommand; each returns `anyhow::Result` with context saying where.

use crate::cli::{Cli, Command};
use anyhow::bail;

mod bench;
pub mod demo;
mod devices;
mod gen;
mod import;
mod info;
mod render;

/// An honest failure for a command whose issue has not landed yet.
fn not_implemented(what: &str, issue: u32) -> anyhow::Result<()> {
    bail!("{what} is not implemented yet: see issue {issue}")
}

pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Devices(a) => devices::run(a),
        Command::Gen(a) => gen::run(a),
        Command::Import(a) => import::run(a),
        Command::Info(a) => info::run(a),
        Command::Verify(a) => info::verify(a),
        Command::Report(_) => not_implemented("motu report", 9),
        Command::Render(a) => render::run(a),
        Command::Compare(a) => render::compare(a),
        Command::Bench(a) => bench::run(a),
        Command::Demo(a) => demo::run(a),
    }
}
