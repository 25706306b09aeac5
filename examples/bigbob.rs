//! `bigbob`: the trash-zapping robot.
//!
//! The capstone of the classic Player/Stage tutorial. Bigbob wanders its
//! yard on sonar; when its camera (a blobfinder) sees orange or blue trash it
//! turns toward the biggest blob and drives at it; when the trash breaks the
//! beam between its teeth, the program asks the simulator where every piece
//! of trash is, picks the one between the teeth, and moves it out of the
//! world: zapped.
//!
//! ```sh
//! troupe launch worlds/bigbob.cfg &
//! cargo run --example bigbob
//! ```
#![allow(clippy::print_stdout)]

use clap::Parser;
use troupe_client::{BlobfinderProxy, Client, RangerProxy, SimulationProxy};
use troupe_examples::Wanderer;

#[derive(Parser)]
struct Args {
    #[command(flatten)]
    common: troupe_examples::Common,
    /// Bigbob's name in the world file.
    #[arg(long, default_value = "bob1")]
    name: String,
    /// The trash, by name in the world file.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "orange1,orange2,orange3,orange4,carton1,carton2,carton3,carton4"
    )]
    items: Vec<String>,
}

/// Where zapped trash goes: far outside the yard.
const NOWHERE: (f64, f64) = (-100.0, -100.0);

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let robot = Client::connect(&args.common.zenoh, args.common.robot)?;
    let mut bob = Wanderer::new(&robot, 0, 0)?;
    let beam = RangerProxy::new(&robot, 1)?;
    let eyes = BlobfinderProxy::new(&robot, 0)?;
    let sim = SimulationProxy::new(&robot, 0);
    // An empty gap reads the beam's full range.
    let gap = beam.request_config()?.max_range;

    robot.read()?;
    let t0 = robot.data_time();
    let mut left: Vec<String> = args.items.clone();
    while !left.is_empty() && !args.common.time_is_up(&robot, t0) {
        robot.read()?;
        let t = robot.data_time() - t0;

        // Something between the teeth? Find which piece it is, and zap it.
        if beam.ranges().iter().any(|&r| r < gap - 0.01) {
            bob.base.set_speed(0.0, 0.0)?;
            let me = sim.get_pose2d(&args.name)?;
            let mut nearest: Option<(f64, usize)> = None;
            for (i, item) in left.iter().enumerate() {
                let p = sim.get_pose2d(item)?;
                let d = (p.x - me.x).hypot(p.y - me.y);
                if nearest.is_none_or(|(best, _)| d < best) {
                    nearest = Some((d, i));
                }
            }
            if let Some((d, i)) = nearest.filter(|&(d, _)| d < 1.0) {
                let item = left.remove(i);
                sim.set_pose2d(&item, NOWHERE.0, NOWHERE.1, 0.0)?;
                println!(
                    "t {t:5.1} s  zapped {item} ({d:.2} m from my centre); {} to go",
                    left.len()
                );
            }
            continue;
        }

        // Trash in sight? Head for the biggest blob: turn in proportion to
        // how far off centre it is, and slow down while turning hard.
        let blobs = eyes.blobs();
        if let Some(b) = blobs.iter().max_by_key(|b| b.area) {
            let half = f64::from(eyes.width().max(2)) / 2.0;
            let off = (half - f64::from(b.x)) / half; // +1 left edge, -1 right edge
            let turn = 0.8 * off;
            let speed = 0.3 * (1.0 - off.abs()).max(0.2);
            bob.base.set_speed(speed, turn)?;
            continue;
        }

        // Nothing to chase: wander.
        bob.step()?;
    }
    bob.base.set_speed(0.0, 0.0)?;
    let zapped = args.items.len() - left.len();
    println!(
        "zapped {zapped} of {} in {:.1} s",
        args.items.len(),
        robot.data_time() - t0
    );
    Ok(())
}
