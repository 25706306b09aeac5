//! `map`: fetch a map and draw it in the terminal.
//!
//! A map device (here Player's `mapfile` driver, serving a bitmap) holds an
//! occupancy grid: each cell is free (-1), unknown (0) or occupied (+1).
//! Request it, print its size and resolution, and draw it with `X` for
//! occupied, `.` for free and `?` for unknown, one character per block of
//! cells so it fits the terminal.
//!
//! ```sh
//! troupe launch worlds/map.cfg &
//! cargo run --example map -- --robot 6665
//! ```
#![allow(clippy::print_stdout)]

use clap::Parser;
use troupe_client::{Client, MapProxy};

#[derive(Parser)]
struct Args {
    #[command(flatten)]
    common: troupe_examples::Common,
    /// Characters per line of the drawing.
    #[arg(long, default_value_t = 64)]
    columns: u32,
    /// Which map device (map.cfg: 0 the bitmap, 1 its obstacles grown by
    /// mapcspace, 2 rescaled by mapscale).
    #[arg(long, default_value_t = 0)]
    index: u32,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let robot = Client::connect(&args.common.zenoh, args.common.robot)?;
    let mut map = MapProxy::new(&robot, args.index);
    map.request_map()?;
    let (w, h) = (map.width(), map.height());
    let o = map.origin();
    println!(
        "map: {w} x {h} cells of {:.3} m ({:.1} m x {:.1} m), cell (0,0) at ({:.2}, {:.2})",
        map.resolution(),
        f64::from(w) * map.resolution(),
        f64::from(h) * map.resolution(),
        o.x,
        o.y
    );

    // One character per `step` x `step` cells; terminal characters are about
    // twice as tall as wide, so a row of characters covers two rows of blocks.
    let step = w.div_ceil(args.columns.max(1)).max(1);
    let (mut free, mut occupied) = (0u64, 0u64);
    for j in 0..h {
        for i in 0..w {
            match map.cell(i, j) {
                Some(c) if c > 0 => occupied += 1,
                Some(c) if c < 0 => free += 1,
                _ => {}
            }
        }
    }
    // Row 0 of the grid is the bottom of the world (y grows upwards): print from the top.
    let mut j = h;
    while j > 0 {
        let top = j.saturating_sub(2 * step);
        let line: String = (0..w)
            .step_by(step as usize)
            .map(|i| block(&map, i..(i + step).min(w), top..j))
            .collect();
        println!("{line}");
        j = top;
    }
    println!("{free} free cells, {occupied} occupied");
    Ok(())
}

/// What a block of cells shows: any occupied cell wins, then any unknown.
fn block(map: &MapProxy, cols: std::ops::Range<u32>, rows: std::ops::Range<u32>) -> char {
    let mut c = '.';
    for j in rows {
        for i in cols.clone() {
            match map.cell(i, j) {
                Some(1..) => return 'X',
                Some(0) | None => c = '?',
                _ => {}
            }
        }
    }
    c
}
