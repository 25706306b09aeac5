//! `two_robots_ports`: a team where every robot has its own port.
//!
//! In Player each robot was usually its own server: robot r0 on port 6665,
//! r1 on 6666, with the same device indexes on both. A client holds one
//! connection per robot. In Troupe the "port" is the robot field of every
//! key (`robot/6665/position2d/0`, `robot/6666/position2d/0`), so one
//! program can drive the whole team over one network session or several.
//!
//! ```sh
//! troupe launch worlds/two_ports.cfg &
//! cargo run --example two_robots_ports -- --robot 6665 --second 6666
//! ```
#![allow(clippy::print_stdout)]

use clap::Parser;
use troupe_client::Client;
use troupe_examples::Wanderer;

#[derive(Parser)]
struct Args {
    #[command(flatten)]
    common: troupe_examples::Common,
    /// The second robot's port.
    #[arg(long, default_value_t = 6666)]
    second: u32,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let first = Client::connect(&args.common.zenoh, args.common.robot)?;
    // The second robot over the same network session: only the port differs.
    let second = Client::with_session(first.session().clone(), args.second);
    let mut robots = [Wanderer::new(&first, 0, 0)?, Wanderer::new(&second, 0, 0)?];
    let ports = [args.common.robot, args.second];

    first.read()?;
    let t0 = first.data_time();
    let mut last_print = f64::NEG_INFINITY;
    while !args.common.time_is_up(&first, t0) {
        // Every robot's data wakes its own client; pace the loop on the first.
        first.read()?;
        for r in &mut robots {
            r.step()?;
        }
        if first.data_time() - last_print >= 1.0 {
            last_print = first.data_time();
            let at: Vec<String> = robots
                .iter()
                .zip(ports)
                .map(|(r, p)| format!("robot {p} at ({:6.2}, {:6.2})", r.base.x(), r.base.y()))
                .collect();
            println!("t {:5.1} s  {}", last_print - t0, at.join("   "));
        }
    }
    for r in &robots {
        r.base.set_speed(0.0, 0.0)?;
    }
    Ok(())
}
