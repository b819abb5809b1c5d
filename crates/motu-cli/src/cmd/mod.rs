//! One module per subcommand; each returns `anyhow::Result` with context saying where.

use crate::cli::{Cli, Command};
use anyhow::bail;

mod devices;
mod gen;

/// An honest failure for a command whose issue has not landed yet.
fn not_implemented(what: &str, issue: u32) -> anyhow::Result<()> {
    bail!("{what} is not implemented yet: see issue {issue}")
}

pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Devices(a) => devices::run(a),
        Command::Gen(a) => gen::run(a),
        Command::Import(_) => not_implemented("motu import", 4),
        Command::Info(_) => not_implemented("motu info", 4),
        Command::Verify(_) => not_implemented("motu verify", 4),
        Command::Report(_) => not_implemented("motu report", 9),
        Command::Render(_) => not_implemented("motu render", 7),
        Command::Compare(_) => not_implemented("motu compare", 5),
        Command::Bench(_) => not_implemented("motu bench", 10),
        Command::Demo(_) => not_implemented("motu demo", 2),
    }
}
