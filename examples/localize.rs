//! `localize`: watch a particle filter find the robot.
//!
//! amcl keeps a cloud of guesses of the robot's pose and summarises them as
//! hypotheses: a mean, a covariance and a weight. Tell it roughly where the
//! robot is (a pose with a generous covariance), drive a slow circle so the
//! laser sees the walls from new places, and watch the best hypothesis
//! settle and its uncertainty shrink.
//!
//! ```sh
//! troupe launch worlds/nav.cfg &
//! cargo run --example localize -- --x -5.5 --y -6.5 --yaw 30
//! ```
#![allow(clippy::print_stdout)]

use clap::Parser;
use troupe_client::{Client, LocalizeProxy, Position2dProxy};
use troupe_msgs::Pose2d;

#[derive(Parser)]
struct Args {
    #[command(flatten)]
    common: troupe_examples::Common,
    /// Where we tell amcl the robot is: x, metres.
    #[arg(long, default_value_t = -5.5, allow_negative_numbers = true)]
    x: f64,
    /// y, metres.
    #[arg(long, default_value_t = -6.5, allow_negative_numbers = true)]
    y: f64,
    /// Heading, degrees.
    #[arg(long, default_value_t = 30.0, allow_negative_numbers = true)]
    yaw: f64,
    /// How sure we are: standard deviation of x and y, metres.
    #[arg(long, default_value_t = 1.0)]
    spread: f64,
    /// Drive for this many seconds of the robot's clock.
    #[arg(long, default_value_t = 30.0)]
    seconds: f64,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let robot = Client::connect(&args.common.zenoh, args.common.robot)?;
    let amcl = LocalizeProxy::new(&robot, 0)?;
    let base = Position2dProxy::new(&robot, 0)?;
    while amcl.hypoths().is_empty() {
        robot.read()?;
    }
    print_hypoths("amcl's own guess", &amcl);

    let mean = Pose2d {
        x: args.x,
        y: args.y,
        yaw: args.yaw.to_radians(),
    };
    let s2 = args.spread * args.spread;
    // Covariance in Player's order: xx, yy, yaw-yaw, xy, y-yaw, x-yaw.
    amcl.set_pose(mean, [s2, s2, 30f64.to_radians().powi(2), 0.0, 0.0, 0.0])?;
    println!(
        "told amcl: near ({}, {}) facing {} deg, give or take {} m",
        args.x, args.y, args.yaw, args.spread
    );

    base.set_motor_enable(true)?;
    // A circle 1.3 m across: it stays clear of the corner walls.
    base.set_speed(0.2, 0.3)?;
    robot.read()?;
    let t0 = robot.data_time();
    let mut next_print = t0 + 5.0;
    while robot.data_time() - t0 < args.seconds {
        robot.read()?;
        if robot.data_time() >= next_print {
            next_print += 5.0;
            print_hypoths(&format!("t {:4.1} s", robot.data_time() - t0), &amcl);
        }
    }
    base.set_speed(0.0, 0.0)?;
    print_hypoths("in the end", &amcl);
    Ok(())
}

fn print_hypoths(when: &str, amcl: &LocalizeProxy) {
    let hs = amcl.hypoths();
    println!("{when}: {} hypotheses", hs.len());
    for h in hs.iter().take(3) {
        println!(
            "    ({:6.2}, {:6.2}) facing {:4.0} deg, std dev {:.2} m, weight {:.2}",
            h.mean.x,
            h.mean.y,
            h.mean.yaw.to_degrees(),
            (h.cov[0] + h.cov[1]).sqrt(),
            h.weight
        );
    }
}
