//! `two_robots_index`: a team on one port, told apart by device index.
//!
//! The other Player style: one server for the whole team, where robot r0's
//! base is position2d:0 and r1's is position2d:1 (and their sonars ranger:0
//! and ranger:1). One client, one robot number, two sets of proxies.
//!
//! ```sh
//! troupe launch worlds/two_index.cfg &
//! cargo run --example two_robots_index -- --robot 6665
//! ```
#![allow(clippy::print_stdout)]

use clap::Parser;
use troupe_client::Client;
use troupe_examples::Wanderer;

fn main() -> anyhow::Result<()> {
    let args = troupe_examples::Common::parse();
    let client = Client::connect(&args.zenoh, args.robot)?;
    // Robot i: position2d:i and ranger:i.
    let mut robots = [Wanderer::new(&client, 0, 0)?, Wanderer::new(&client, 1, 1)?];

    client.read()?;
    let t0 = client.data_time();
    let mut last_print = f64::NEG_INFINITY;
    while !args.time_is_up(&client, t0) {
        client.read()?;
        for r in &mut robots {
            r.step()?;
        }
        if client.data_time() - last_print >= 1.0 {
            last_print = client.data_time();
            let at: Vec<String> = robots
                .iter()
                .enumerate()
                .map(|(i, r)| format!("position2d:{i} at ({:6.2}, {:6.2})", r.base.x(), r.base.y()))
                .collect();
            println!("t {:5.1} s  {}", last_print - t0, at.join("   "));
        }
    }
    for r in &robots {
        r.base.set_speed(0.0, 0.0)?;
    }
    Ok(())
}
