//! `troupe`: one binary for every Troupe process and tool.
//!
//! This crate only wires: `cli` defines the command line, `drivers` lists
//! the drivers this binary links, and `run` hands each subcommand to the
//! crate that does it (the launcher, a driver, a tool). Errors travel back
//! up as `anyhow` chains and are printed whole; the exit code says whether
//! the command succeeded.

mod cli;
#[cfg(test)]
mod docs;
mod drivers;
#[cfg(test)]
mod samples;

use std::io::Write;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};

use clap::Parser;

/// Set by the panic hook: a panic on any thread fails the command, even
/// one its main thread outlived.
static PANICKED: AtomicBool = AtomicBool::new(false);

fn main() -> ExitCode {
    let report = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        PANICKED.store(true, Ordering::SeqCst);
        report(info);
    }));
    let cli = cli::Cli::parse();
    troupe_node::init_logging(cli.log.as_deref());
    let result = run(cli);
    if PANICKED.load(Ordering::SeqCst) {
        let _ = writeln!(
            std::io::stderr(),
            "troupe: error: a thread panicked (above)"
        );
        return ExitCode::from(101);
    }
    match result {
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
        Command::Launch(a) => troupe_launch::supervisor::launch(a, z, &drivers::catalog()),
        Command::Plan(a) => troupe_launch::supervisor::print_plan(a, &drivers::catalog()),
        Command::Node(a) => troupe_launch::node::run(a, z, &drivers::catalog()),
        Command::Router(a) => troupe_launch::router::run(a, z),
        Command::List(a) => troupe_inspect::list(a, z),
        Command::Echo(a) => troupe_inspect::echo(a, z),
        Command::Hz(a) => troupe_inspect::hz(a, z),
        Command::Cmd(a) => troupe_inspect::cmd(a, z),
        Command::Call(a) => troupe_inspect::call(a, z),
        Command::Ready(a) => troupe_inspect::ready(a, z),
        Command::Drivers { all } => troupe_inspect::print_drivers(&drivers::catalog(), all),
        Command::Interfaces => troupe_inspect::print_interfaces(),
        Command::Record(a) => troupe_record::record(a, z),
        Command::Foxglove(a) => troupe_foxglove::serve(&a, z),
        Command::Play(a) => troupe_record::play(a, z),
        Command::Log(c) => troupe_record::log(c),
        Command::View(a) => troupe_view::run(a, z),
        Command::Emulate(a) => troupe_emulate::run(a, z),
        Command::Bench(b) => troupe_bench::run(b, z),
        Command::Map(c) => troupe_map::run(c, z),
        Command::Bridge(a) => troupe_bridge::command::run(a, z),
        Command::Image(a) => troupe_fleet::docker::image(a),
        Command::Compose(a) => troupe_fleet::docker::compose(a, &drivers::catalog()),
        Command::FleetKeys(a) => troupe_fleet::keys::fleet_keys(a),
    }
}
