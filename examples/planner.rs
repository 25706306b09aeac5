//! `planner`: send the robot across the building and follow its progress.
//!
//! Four drivers cooperate: amcl says where the robot is on the map, wavefront
//! plans a path over the map and hands its waypoints one by one to vfh, and
//! vfh steers the base around whatever its laser sees. The client only talks
//! to the planner: it sets a goal, switches the planner on, and watches the
//! plan become valid, the waypoints go by, and the goal reached.
//!
//! ```sh
//! troupe launch worlds/nav.cfg &
//! cargo run --example planner -- --x 5 --y 0
//! ```
#![allow(clippy::print_stdout)]

use clap::Parser;
use troupe_client::{Client, PlannerProxy};

#[derive(Parser)]
struct Args {
    #[command(flatten)]
    common: troupe_examples::Common,
    /// Goal x, metres.
    #[arg(long, default_value_t = 5.0, allow_negative_numbers = true)]
    x: f64,
    /// Goal y, metres.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    y: f64,
    /// Goal heading, degrees.
    #[arg(long, default_value_t = 90.0, allow_negative_numbers = true)]
    yaw: f64,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let robot = Client::connect(&args.common.zenoh, args.common.robot)?;
    let planner = PlannerProxy::new(&robot, 0)?;
    // The planner speaks once it has a map and a pose.
    while planner.state().is_none() {
        robot.read()?;
    }
    planner.set_goal_pose(args.x, args.y, args.yaw.to_radians())?;
    planner.set_enable(true)?;
    println!("goal ({}, {}) facing {} deg", args.x, args.y, args.yaw);

    let t0 = robot.data_time();
    let mut valid = false;
    let mut heading_for = None;
    loop {
        robot.read()?;
        let Some(s) = planner.state() else { continue };
        // Until the planner has taken our goal, its state is about the old one.
        if (s.goal.x - args.x).hypot(s.goal.y - args.y) > 1e-6 {
            continue;
        }
        let t = robot.data_time() - t0;
        if s.valid && !valid {
            let path = planner.request_waypoints()?;
            println!("t {t:5.1} s  a path of {} waypoints:", path.len());
            for (i, p) in path.iter().enumerate() {
                println!("    {i:2}: ({:6.2}, {:6.2})", p.x, p.y);
            }
        }
        valid = s.valid;
        // The planner replans as it goes; say when the next waypoint changes.
        let next = (s.waypoint.x, s.waypoint.y);
        if s.valid && !s.done && heading_for != Some(next) {
            heading_for = Some(next);
            println!(
                "t {t:5.1} s  at ({:6.2}, {:6.2}), heading for ({:.2}, {:.2})",
                s.pose.x, s.pose.y, next.0, next.1
            );
        }
        if s.done {
            println!(
                "t {t:5.1} s  arrived at ({:.2}, {:.2}) facing {:.0} deg",
                s.pose.x,
                s.pose.y,
                s.pose.yaw.to_degrees()
            );
            return Ok(());
        }
        if args.common.time_is_up(&robot, t0) {
            planner.set_enable(false)?;
            anyhow::bail!("not there after {} s", args.common.run_for);
        }
    }
}
