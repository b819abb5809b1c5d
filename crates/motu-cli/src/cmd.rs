//! One module per subcommand; each returns `anyhow::Result` with context saying where.

use crate::cli::{Cli, Command};

mod bench;
pub mod demo;
mod devices;
mod gen;
mod import;
mod info;
pub mod render;
mod report;
mod view;

pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Devices(a) => devices::run(a),
        Command::Gen(a) => gen::run(a),
        Command::Import(a) => import::run(a),
        Command::Info(a) => info::run(a),
        Command::Verify(a) => info::verify(a),
        Command::Report(a) => report::run(a),
        Command::Render(a) => render::run(a),
        Command::View(a) => view::run(a),
        Command::Compare(a) => render::compare(a),
        Command::Bench(a) => bench::run(a),
        Command::Demo(a) => demo::run(a),
    }
}
