//! `laser`: print what a laser sees, like Player's laser tutorial.
//!
//! ```sh
//! troupe launch worlds/laser.cfg &
//! cargo run --example laser -- --robot 6665
//! ```
#![allow(clippy::print_stdout)]

use clap::Parser;
use troupe_client::{Client, LaserProxy};

fn main() -> anyhow::Result<()> {
    let args = troupe_examples::Common::parse();
    let robot = Client::connect(&args.zenoh, args.robot)?;
    let lp = LaserProxy::new(&robot, 0)?;
    for _ in 0..5 {
        robot.read()?;
        println!(
            "{} beams from {:.3} to {:.3} rad, every {:.4} rad, max range {:.1} m",
            lp.count(),
            lp.min_angle(),
            lp.max_angle(),
            lp.scan_res(),
            lp.max_range()
        );
        let n = lp.count();
        let picks = [0, n / 4, n / 2, 3 * n / 4, n.saturating_sub(1)];
        let ranges: Vec<String> = picks
            .iter()
            .filter_map(|&i| lp.range(i).map(|r| format!("[{i}] {r:.2} m")))
            .collect();
        println!("  {}", ranges.join("  "));
    }
    Ok(())
}
