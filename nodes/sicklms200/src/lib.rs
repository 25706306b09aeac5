//! Player's `sicklms200`: the SICK LMS200 laser over a serial line.
//!
//! ```text
//! driver ( name "sicklms200" provides ["laser:0"] port "/dev/ttyUSB0"
//!          resolution 50 range_res 1 transfer_rate 38400 )
//! ```
//!
//! | | |
//! |---|---|
//! | provides | one `laser` |
//! | requires | none |
//! | options | Player's: `port` ("/dev/ttyS1"), `connect_rate` ([9600 38400 500000]), `transfer_rate` (38400), `retry` (0), `delay` (0 s), `resolution` (50: 25, 50 or 100 hundredths of a degree), `range_res` (1: 1, 10 or 100 mm), `invert` (0), `pose` ([0 0 0]), `size` ([0.15 0.15]), `high_avail` (0) |
//!
//! # Behavior
//!
//! - The line is driven on a thread of its own ([`device`]): Player's
//!   connection sequence, then continuous scans. Each scan is published as
//!   a [`laser::Scan`] in metres and radians with the intensity bits, ids
//!   counting up, reversed when `invert` is set.
//! - The laser is *not ready* (its liveliness withdrawn) until the scanner
//!   streams, and again whenever the session fails — no answer, a refusal,
//!   a lost device, scans that stop for longer than three telegrams' line
//!   time (at least 1 s). It retries every 2 s, logging why and the counts
//!   of bad checksums, noise bytes and malformed scans. Nothing panics.
//! - `geom` answers `pose` and `size`; `get_config` the scan in Player's
//!   units; `set_config` rescans (resolution in radians, or in Player's
//!   hundredths of a degree as its driver read it; range resolution in
//!   metres, or millimetres) and answers once the scanner has taken it.
//! - On shutdown it stops the stream and puts the scanner back at its first
//!   connect rate, as Player's `MainQuit`.
//! - `serial_high_speed_mode` and `serial_high_speed_baudremap` are accepted
//!   and unused: Linux sets 500000 baud directly. `pls_mode` is refused.

pub mod device;
pub mod emulator;
pub mod telegram;

use std::collections::VecDeque;
use std::path::PathBuf;
use std::time::Duration;

use serde::Deserialize;
use troupe_msgs::{laser, Device, Interface, Pose3d, Size3d};
use troupe_node::{Ctx, Driver, Event, NodeError, Responder, Result, Section, Unit};
use troupe_serial::HeldLine;

use crate::device::{Line, Order, ScanConfig, Settings, Update};
use crate::telegram::RawScan;

/// Options, by Player's names.
#[derive(Debug, Deserialize)]
#[serde(default)]
#[allow(missing_docs)]
pub struct Options {
    pub port: PathBuf,
    pub connect_rate: Vec<u32>,
    pub transfer_rate: u32,
    pub retry: u32,
    pub delay: u64,
    pub resolution: u16,
    pub range_res: u32,
    pub invert: i64,
    pub pose: [f64; 3],
    pub size: [f64; 2],
    pub high_avail: i64,
    pub pls_mode: i64,
    pub serial_high_speed_mode: i64,
    pub serial_high_speed_baudremap: i64,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            port: "/dev/ttyS1".into(),
            connect_rate: vec![9600, 38400, 500000],
            transfer_rate: 38400,
            retry: 0,
            delay: 0,
            resolution: 50,
            range_res: 1,
            invert: 0,
            pose: [0.0; 3],
            size: [0.15, 0.15],
            high_avail: 0,
            pls_mode: 0,
            serial_high_speed_mode: 0,
            serial_high_speed_baudremap: 38400,
        }
    }
}

/// The rates the LMS200 can talk at.
const LMS_RATES: [u32; 4] = [9600, 19200, 38400, 500000];

/// The sicklms200 driver.
pub struct SickLms200 {
    laser: Device,
    settings: Settings,
    invert: bool,
    pose: [f64; 3],
    size: [f64; 2],
    config: ScanConfig,
    line: Option<Line>,
    scan_id: u32,
    /// `set_config` requests waiting for the scanner, in order.
    pending: VecDeque<Responder>,
}

impl Driver for SickLms200 {
    const NAME: &'static str = "sicklms200";
    type Options = Options;
    // Player reads all three pose elements with ReadTupleLength (the yaw too).
    const UNITS: &'static [(&'static str, Unit)] =
        &[("pose", Unit::Lengths), ("size", Unit::Lengths)];

    fn new(section: &Section, o: Options) -> Result<Self> {
        let bad = |why: String| NodeError::config(Self::NAME, why);
        if o.pls_mode != 0 {
            return Err(bad(
                "pls_mode: the SICK PLS is not supported, only the LMS200".into(),
            ));
        }
        if o.connect_rate.is_empty() {
            return Err(bad(
                "connect_rate is empty: give at least one of 9600, 38400, 500000".into(),
            ));
        }
        for &r in o.connect_rate.iter().chain([&o.transfer_rate]) {
            if !LMS_RATES.contains(&r) {
                return Err(bad(format!(
                    "baud rate {r} is not one the LMS200 talks at (9600, 19200, 38400, 500000)"
                )));
            }
        }
        let config = ScanConfig {
            res: o.resolution,
            range_res: o.range_res,
            intensity: true,
            min_angle: -9000,
            max_angle: 9000,
        };
        config.check().map_err(|e| bad(e.to_string()))?;
        Ok(SickLms200 {
            laser: section.provided_one(Interface::Laser, None)?,
            settings: Settings {
                port: o.port,
                connect_rates: o.connect_rate,
                transfer_rate: o.transfer_rate,
                retry: o.retry,
                delay: Duration::from_secs(o.delay),
                high_avail: o.high_avail != 0,
                config,
            },
            invert: o.invert != 0,
            pose: o.pose,
            size: o.size,
            config,
            line: None,
            scan_id: 0,
            pending: VecDeque::new(),
        })
    }

    fn setup(&mut self, ctx: &mut Ctx) -> Result<()> {
        ctx.set_ready(false);
        // The mounting is the cfg's: answered without waking this thread.
        ctx.answer_always::<laser::GetGeom>(&self.laser, &self.geom())?;
        let line = device::spawn(self.settings.clone(), ctx.waker())
            .map_err(|e| NodeError::Driver(format!("starting the line thread: {e}").into()))?;
        tracing::info!("laser initialising ({})", self.settings.port.display());
        self.line = Some(line);
        Ok(())
    }

    fn on_event(&mut self, ctx: &mut Ctx, event: Event) -> Result<()> {
        match event {
            Event::Wake => self.drain(ctx),
            Event::Request(r) if r.is::<laser::GetConfig>() => {
                r.reply(&player_config(&self.config));
                Ok(())
            }
            Event::Request(r) if r.is::<laser::SetConfig>() => {
                let want = r.decode::<laser::SetConfig>()?.config;
                let c = from_player(&want);
                match (c.check(), &self.line) {
                    (Err(why), _) => r.nack(format!("invalid laser configuration: {why}")),
                    (Ok(()), Some(line)) => {
                        if line.send(Order::Configure(c)) {
                            self.pending.push_back(r.responder);
                        } else {
                            r.nack("the laser's line thread has stopped");
                        }
                    }
                    (Ok(()), None) => r.nack("the laser is not set up"),
                }
                Ok(())
            }
            Event::Request(r) => {
                r.unhandled(Self::NAME);
                Ok(())
            }
            Event::Command(c) => Err(c.unexpected()),
            Event::Data(_) | Event::Reply(_) | Event::Tick => Ok(()),
        }
    }

    fn shutdown(&mut self, _: &mut Ctx) -> Result<()> {
        self.line.stop_with(Order::Stop);
        tracing::info!(scans = self.scan_id, "laser shutdown");
        Ok(())
    }
}

impl SickLms200 {
    fn geom(&self) -> laser::Geom {
        laser::Geom {
            pose: Pose3d::planar(self.pose[0], self.pose[1], self.pose[2]),
            size: Size3d {
                length: self.size[0],
                width: self.size[1],
                height: 0.0,
            },
        }
    }

    fn drain(&mut self, ctx: &mut Ctx) -> Result<()> {
        for u in self.line.updates_now() {
            match u {
                Update::Ready { kind, baud } => {
                    tracing::info!("laser ready: {kind} at {baud} baud");
                    ctx.set_ready(true);
                }
                Update::Lost(why) => {
                    if ctx.is_ready() {
                        tracing::warn!("laser lost: {why}");
                    }
                    ctx.set_ready(false);
                }
                Update::Scan(raw, config) => {
                    let scan = to_scan(&raw, &config, self.invert, self.scan_id);
                    self.scan_id = self.scan_id.wrapping_add(1);
                    ctx.publish(&self.laser, &scan)?;
                }
                Update::Configured(result) => {
                    let Some(responder) = self.pending.pop_front() else {
                        continue;
                    };
                    match result {
                        Ok(c) => {
                            self.config = c;
                            responder.reply(&player_config(&c));
                        }
                        Err(why) => {
                            responder.nack(format!("the laser refused the configuration: {why}"))
                        }
                    }
                }
            }
        }
        Ok(())
    }
}

/// A scan in Player's units: Player's `Main`.
pub fn to_scan(raw: &RawScan, c: &ScanConfig, invert: bool, id: u32) -> laser::Scan {
    let (first, last) = c.segments();
    let res = f64::from(c.res) / 100.0;
    let half = f64::from(c.width()) / 2.0;
    let angle = |seg: u16| (f64::from(seg) * res - half).to_radians() as f32;
    let unit = c.range_res as f32 / 1000.0;
    let mut ranges: Vec<f32> = raw
        .values
        .iter()
        .map(|v| f32::from(v & 0x1FFF) * unit)
        .collect();
    let mut intensity: Vec<u8> = raw.values.iter().map(|v| ((v >> 13) & 0x7) as u8).collect();
    if invert {
        ranges.reverse();
        intensity.reverse();
    }
    laser::Scan {
        min_angle: angle(first),
        max_angle: angle(last),
        resolution: res.to_radians() as f32,
        max_range: c.max_range(),
        ranges,
        intensity,
        id,
    }
}

fn player_config(c: &ScanConfig) -> laser::Config {
    let interlace = match c.res {
        25 => 4.0,
        50 => 2.0,
        _ => 1.0,
    };
    laser::Config {
        min_angle: (f64::from(c.min_angle) / 100.0).to_radians() as f32,
        max_angle: (f64::from(c.max_angle) / 100.0).to_radians() as f32,
        resolution: (f64::from(c.res) / 100.0).to_radians() as f32,
        max_range: c.max_range(),
        range_res: c.range_res as f32 / 1000.0,
        intensity: c.intensity,
        scanning_frequency: 75.0 / interlace,
    }
}

/// A client's configuration in the scanner's units. Player's own driver
/// read `resolution` as hundredths of a degree and `range_res` as mm;
/// values that can only mean that are taken so, others as radians and metres.
fn from_player(c: &laser::Config) -> ScanConfig {
    let res = if c.resolution >= 1.0 {
        c.resolution.round() as u16
    } else {
        (f64::from(c.resolution).to_degrees() * 100.0).round() as u16
    };
    let range_res = if c.range_res >= 1.0 {
        c.range_res.round() as u32
    } else {
        (f64::from(c.range_res) * 1000.0).round() as u32
    };
    let cdeg = |a: f32| (f64::from(a).to_degrees() * 100.0).round() as i32;
    ScanConfig {
        res,
        range_res,
        intensity: c.intensity,
        min_angle: cdeg(c.min_angle),
        max_angle: cdeg(c.max_angle),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config(res: u16) -> ScanConfig {
        ScanConfig {
            res,
            range_res: 1,
            intensity: true,
            min_angle: -9000,
            max_angle: 9000,
        }
    }

    #[test]
    fn segments_follow_players_check_scan_config() {
        assert_eq!(config(50).segments(), (0, 360));
        assert_eq!(config(100).segments(), (0, 180));
        assert_eq!(config(25).segments(), (0, 400));
        let narrow = ScanConfig {
            min_angle: -4500,
            max_angle: 4500,
            ..config(50)
        };
        assert_eq!(narrow.segments(), (90, 270));
        assert_eq!(narrow.count(), 181);
    }

    #[test]
    fn a_raw_scan_becomes_players_laser_data() {
        let raw = RawScan {
            values: vec![1000, 2000 | (3 << 13), 8183],
            units: 1,
            status: 0,
        };
        let c = ScanConfig {
            min_angle: -100,
            max_angle: 100,
            res: 100,
            ..config(100)
        };
        let s = to_scan(&raw, &c, false, 7);
        let near = |a: &[f32], b: &[f32]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-5);
        assert!(near(&s.ranges, &[1.0, 2.0, 8.183]), "{:?}", s.ranges);
        assert_eq!(s.intensity, vec![0, 3, 0]);
        assert!((s.min_angle - (-1.0f32).to_radians()).abs() < 1e-6);
        assert!((s.max_angle - 1.0f32.to_radians()).abs() < 1e-6);
        assert_eq!((s.max_range, s.id), (8.0, 7));
        let inv = to_scan(&raw, &c, true, 0);
        assert!(near(&inv.ranges, &[8.183, 2.0, 1.0]), "{:?}", inv.ranges);
        assert_eq!(inv.intensity, vec![0, 3, 0]);
    }

    #[test]
    fn client_configs_in_either_unit_convention() {
        let mut c = player_config(&config(50));
        assert_eq!(from_player(&c), config(50));
        c.resolution = 100.0;
        c.range_res = 10.0;
        let got = from_player(&c);
        assert_eq!((got.res, got.range_res), (100, 10));
        c.resolution = 0.3f32.to_radians();
        assert!(from_player(&c).check().is_err());
    }
}
