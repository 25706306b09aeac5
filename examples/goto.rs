//! `goto`: let the robot's own controller take it to a pose.
//!
//! Ask the base its size, switch its motors on, give it a target pose
//! (Player's position2d "position control"), and print where it is until it
//! gets there. Targets, like the pose the base reports, are in odometry
//! coordinates: they start at (0, 0) facing 0 where the robot started, x
//! ahead and y to its left.
//!
//! ```sh
//! troupe launch worlds/simple.cfg &
//! cargo run --example goto -- --robot 6665 --x 2 --y 1 --yaw 90
//! ```
#![allow(clippy::print_stdout)]

use clap::Parser;
use troupe_client::{Client, Position2dProxy};

#[derive(Parser)]
struct Args {
    #[command(flatten)]
    common: troupe_examples::Common,
    /// Target x, metres.
    #[arg(long, default_value_t = 2.0, allow_negative_numbers = true)]
    x: f64,
    /// Target y, metres.
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    y: f64,
    /// Target heading, degrees.
    #[arg(long, default_value_t = 90.0, allow_negative_numbers = true)]
    yaw: f64,
    /// Close enough, metres.
    #[arg(long, default_value_t = 0.1)]
    epsilon: f64,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let robot = Client::connect(&args.common.zenoh, args.common.robot)?;
    let pp = Position2dProxy::new(&robot, 0)?;

    let geom = pp.request_geom()?;
    println!(
        "the base is {:.2} m long and {:.2} m wide",
        geom.size.length, geom.size.width
    );
    pp.set_motor_enable(true)?;
    pp.go_to(args.x, args.y, args.yaw.to_radians())?;
    println!("going to ({}, {}) facing {} deg", args.x, args.y, args.yaw);

    robot.read()?;
    let t0 = robot.data_time();
    let mut last_print = f64::NEG_INFINITY;
    loop {
        robot.read()?;
        let off = (pp.x() - args.x).hypot(pp.y() - args.y);
        let turn = (pp.yaw() - args.yaw.to_radians()).sin().abs();
        if robot.data_time() - last_print >= 1.0 {
            last_print = robot.data_time();
            println!(
                "t {:5.1} s  at ({:6.2}, {:6.2}) facing {:4.0} deg, {off:.2} m to go",
                last_print - t0,
                pp.x(),
                pp.y(),
                pp.yaw().to_degrees()
            );
        }
        if off < args.epsilon && turn < 0.05 {
            println!("arrived after {:.1} s", robot.data_time() - t0);
            return Ok(());
        }
        if args.common.time_is_up(&robot, t0) {
            anyhow::bail!("not there after {} s", args.common.run_for);
        }
    }
}
