//! `wander`: drive around without hitting anything, on sonar alone.
//!
//! The first lesson of every Player course: read a range sensor and a
//! position2d, and steer with three rules. Closer than 0.4 m ahead, stop and
//! turn on the spot; closer than 0.7 m, slow down and turn away; otherwise
//! go straight.
//!
//! ```sh
//! troupe launch worlds/simple.cfg &
//! cargo run --example wander -- --robot 6665
//! ```
#![allow(clippy::print_stdout)]

use clap::Parser;
use troupe_client::{Client, Position2dProxy, RangerProxy};

fn main() -> anyhow::Result<()> {
    let args = troupe_examples::Common::parse();
    let robot = Client::connect(&args.zenoh, args.robot)?;
    let pp = Position2dProxy::new(&robot, 0)?;
    // ranger:0 is the robot's sonar ring; each sonar points its own way.
    let sonar = RangerProxy::new(&robot, 0)?;
    let bearings: Vec<f64> = sonar
        .request_geom()?
        .element_poses
        .iter()
        .map(|p| p.yaw)
        .collect();
    println!("{} sonars; wandering", bearings.len());

    pp.set_motor_enable(true)?;
    robot.read()?;
    let t0 = robot.data_time();
    let (mut turning, mut last_print) = (0.0, f64::NEG_INFINITY);
    while !args.time_is_up(&robot, t0) {
        robot.read()?;
        let ranges = sonar.ranges();
        if ranges.len() != bearings.len() {
            continue; // no scan yet
        }
        let (speed, turn) = troupe_examples::wander(&ranges, &bearings, &mut turning);
        pp.set_speed(speed, turn)?;
        if robot.data_time() - last_print >= 1.0 {
            last_print = robot.data_time();
            println!(
                "t {:6.1} s  at ({:6.2}, {:6.2}) facing {:4.0} deg  speed {speed:.2} turn {:4.0} deg/s{}",
                last_print - t0,
                pp.x(),
                pp.y(),
                pp.yaw().to_degrees(),
                turn.to_degrees(),
                if pp.stall() { "  STALLED" } else { "" }
            );
        }
    }
    pp.set_speed(0.0, 0.0)?;
    Ok(())
}
