//! `gripper`: fetch a box.
//!
//! A gripper reports whether its paddles are open, closed or moving, and two
//! break beams between them. Open the paddles, creep forward until something
//! breaks a beam, close on it, and back up, dragging it along. (Stage's
//! gripper never counts what it stores: closed paddles with a beam still
//! broken are what holding something looks like.)
//!
//! ```sh
//! troupe launch worlds/gripper.cfg &
//! cargo run --example gripper
//! ```
#![allow(clippy::print_stdout)]

use clap::Parser;
use troupe_client::{Client, GripperProxy, Position2dProxy};
use troupe_msgs::gripper::State;

#[derive(Parser)]
struct Args {
    #[command(flatten)]
    common: troupe_examples::Common,
    /// How far to drag the box back, metres.
    #[arg(long, default_value_t = 1.5)]
    back: f64,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let robot = Client::connect(&args.common.zenoh, args.common.robot)?;
    let base = Position2dProxy::new(&robot, 0)?;
    let gripper = GripperProxy::new(&robot, 0)?;
    let t0 = {
        robot.read()?;
        robot.data_time()
    };
    let give_up = |what: &str| -> anyhow::Result<()> {
        if args.common.time_is_up(&robot, t0) {
            base.set_speed(0.0, 0.0)?;
            anyhow::bail!("gave up {what} after {} s", args.common.run_for);
        }
        Ok(())
    };

    // 1. Open up and creep forward until a beam breaks.
    gripper.open()?;
    base.set_motor_enable(true)?;
    println!("approaching with the paddles open");
    base.set_speed(0.15, 0.0)?;
    while gripper.beams() == 0 {
        robot.read()?;
        give_up("looking for something to grip")?;
    }
    base.set_speed(0.0, 0.0)?;
    println!(
        "beams {:#04b} broken at ({:.2}, {:.2}): closing",
        gripper.beams(),
        base.x(),
        base.y()
    );

    // 2. Close, and wait until the paddles stop on it.
    gripper.close()?;
    let mut moving = false;
    while gripper.state() != State::Closed || gripper.beams() == 0 {
        robot.read()?;
        moving |= gripper.state() == State::Moving;
        give_up("closing")?;
    }
    println!(
        "holding it: closed{}, beams {:#04x}",
        if moving { " after moving" } else { "" },
        gripper.beams()
    );

    // 3. Back up, dragging it along.
    let (x0, y0) = (base.x(), base.y());
    base.set_speed(-0.2, 0.0)?;
    while (base.x() - x0).hypot(base.y() - y0) < args.back {
        robot.read()?;
        give_up("backing up")?;
    }
    base.set_speed(0.0, 0.0)?;
    println!(
        "dragged it {:.2} m back to ({:.2}, {:.2}); beams {:#04x}",
        (base.x() - x0).hypot(base.y() - y0),
        base.x(),
        base.y(),
        gripper.beams()
    );
    Ok(())
}
