//! Shared flags of the example programs: the robot to talk to and the network.

use clap::Parser;
use troupe_node::ZenohArgs;

/// `--robot PORT` plus Troupe's network flags.
#[derive(Debug, Parser)]
pub struct Args {
    /// The robot (Player's port).
    #[arg(short = 'p', long, default_value_t = 6665)]
    pub robot: u32,
    /// Network flags, as for every `troupe` command.
    #[command(flatten)]
    pub zenoh: ZenohArgs,
}
