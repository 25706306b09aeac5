//! `troupe`: one binary for every Troupe process and tool.
//!
//! `main` parses the command line and hands it to `run`, which dispatches on
//! the subcommand; errors travel back up as `anyhow` chains and are printed
//! whole, and the exit code says whether the command succeeded.

mod bench;
mod bridge;
mod bridgebench;
mod cfg;
mod cli;
mod docker;
mod drivers;
mod emulate;
mod keys;
mod mcaplog;
mod navbench;
mod passthrough;
mod plan;
mod raybench;
mod serialbench;
mod supervisor;
mod tools;
mod view;
mod viewbench;

use std::io::Write;
use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let cli = cli::Cli::parse();
    troupe_node::init_logging(cli.log.as_deref());
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            if e.chain().any(|c| {
                c.downcast_ref::<std::io::Error>()
                    .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
            }) {
                return ExitCode::SUCCESS;
            }
            // Ignore a failed write: there is nobody left to tell.
            let _ = writeln!(std::io::stderr(), "troupe: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: cli::Cli) -> anyhow::Result<()> {
    use cli::Command;
    let z = &cli.zenoh;
    match cli.command {
        Command::Launch(a) => supervisor::launch(a, z),
        Command::Plan(a) => supervisor::print_plan(a),
        Command::Node(a) => cli::node(a, z),
        Command::List(a) => tools::list(a, z),
        Command::Echo(a) => tools::echo(a, z),
        Command::Hz(a) => tools::hz(a, z),
        Command::Ready(a) => tools::ready(a, z),
        Command::Router(a) => tools::router(a, z),
        Command::Record(a) => mcaplog::record(a, z),
        Command::View(a) => view::run(a, z),
        Command::Play(a) => mcaplog::play(a, z),
        Command::Log(c) => mcaplog::log(c),
        Command::Emulate(a) => emulate::run(a, z),
        Command::Drivers { all } => tools::print_drivers(all),
        Command::Interfaces => tools::print_interfaces(),
        Command::Bench(b) => bench::run(b, z),
        Command::Bridge(a) => bridge::run(a, z),
        Command::Image(a) => docker::image(a),
        Command::Compose(a) => docker::compose(a),
        Command::FleetKeys(a) => keys::fleet_keys(a),
    }
}
