//! Player's `urglaser`: the Hokuyo URG-04LX laser over RS-232 or USB.
//!
//! ```text
//! driver ( name "urglaser" provides ["laser:0"] port "/dev/ttyS1"
//!          use_serial 1 baud 115200 min_angle -115 max_angle 115 )
//! ```
//!
//! | | |
//! |---|---|
//! | provides | one `laser` |
//! | requires | none |
//! | options | Player's: `port` ("/dev/ttyACM0"), `use_serial` (0: USB), `baud` (115200: 19200, 57600 or 115200 over RS-232), `pose` ([0 0 0]), `min_angle`, `max_angle` ([−120 120]°) |
//!
//! # Behavior
//!
//! - The line is driven on a thread of its own ([`device`]), as Player's
//!   `urg_laser` drives it: over RS-232 the rate is found (19200, 57600,
//!   115200) and switched to `baud`, and the URG is spoken to in SCIP 1.1;
//!   over USB a URG with firmware 3 or later is switched to SCIP 2.0, whose
//!   lines carry checksums.
//! - Scans are Player's: the steps between `min_angle` and `max_angle`
//!   (within the 44–725 the URG-04LX measures, with a warning when the cfg
//!   asks for more), `max_i − min_i` ranges from `min_i`, 360°/1024 apart;
//!   readings below 20 mm (the URG's error codes) read as the maximum
//!   range. Unlike Player's, the scan ids count up.
//! - The laser is *not ready* (its liveliness withdrawn) until the URG
//!   answers, and again whenever the session fails — no answer, a refusal,
//!   a lost device, three scan requests in a row unanswered. It retries
//!   every 2 s, logging why; a damaged scan is dropped and counted.
//!   Nothing panics.
//! - `geom` answers `pose` and a 5 cm square; `get_config` the URG's
//!   scan in Player's units (range resolution 1 mm, 10 Hz: Player's own
//!   driver left both uninitialised); `get_id` its serial number.
//!   `set_config` is refused, as Player's driver refused it.

pub mod device;
pub mod emulator;
pub mod scip;

use std::path::PathBuf;

use serde::Deserialize;
use troupe_msgs::{laser, Device, Interface, Pose3d, Size3d};
use troupe_node::{Ctx, Driver, Event, NodeError, Responder, Result, Section, Unit};
use troupe_serial::HeldLine;

use crate::device::{Line, Order, Settings, Update};
use crate::scip::Specs;

/// Options, by Player's names.
#[derive(Debug, Deserialize)]
#[serde(default)]
#[allow(missing_docs)]
pub struct Options {
    pub port: PathBuf,
    pub use_serial: i64,
    pub baud: i64,
    pub pose: [f64; 3],
    pub min_angle: f64,
    pub max_angle: f64,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            port: "/dev/ttyACM0".into(),
            use_serial: 0,
            baud: 115200,
            pose: [0.0; 3],
            min_angle: (-120f64).to_radians(),
            max_angle: 120f64.to_radians(),
        }
    }
}

/// The rates Player's driver switches a URG to.
const URG_RATES: [i64; 3] = [19200, 57600, 115200];

/// Which steps a scan publishes, and in what units: Player's `MainSetup`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Window {
    /// First step published.
    pub min_i: u16,
    /// One past the last step published (Player's `max_i`: its scans hold
    /// `max_i − min_i` ranges).
    pub max_i: u16,
    /// Radians between steps.
    pub resolution: f64,
    /// Metres.
    pub max_range: f64,
    /// Mirror revolutions per second.
    pub frequency: f64,
}

impl Window {
    /// The steps between the cfg's `min`/`max` angles (radians) that the
    /// URG measures, with Player's rounding; a warning for each side the
    /// URG cannot give.
    pub fn new(specs: &Specs, min: f64, max: f64) -> Window {
        let resolution = std::f64::consts::TAU / f64::from(specs.ares);
        let half = f64::from(scip::STEPS / 2);
        let index = |a: f64| (half + a / resolution).round();
        let (lo, hi) = (f64::from(specs.first_step), f64::from(specs.last_step));
        let mut user_min = index(min);
        let user_max = index(max);
        if user_min > user_max {
            user_min = user_max;
        }
        if user_min < lo {
            tracing::warn!("restricting the lower index bound to {lo} from {user_min}");
        }
        if user_max > hi {
            tracing::warn!("restricting the upper index bound to {hi} from {user_max}");
        }
        let step = |v: f64| v as u16;
        Window {
            min_i: step(user_min.max(lo)),
            max_i: step(user_max.min(hi)),
            resolution,
            max_range: f64::from(specs.max_range_mm) / 1000.0,
            frequency: f64::from(specs.rpm) / 60.0,
        }
    }

    fn angle(&self, i: u16) -> f32 {
        ((f64::from(i) - f64::from(scip::STEPS / 2)) * self.resolution) as f32
    }

    /// A scan of readings for steps 0..=768, as Player's `Main` publishes it.
    pub fn scan(&self, readings: &[u32], id: u32) -> laser::Scan {
        let max = self.max_range as f32;
        let from = usize::from(self.min_i);
        let to = usize::from(self.max_i).min(readings.len());
        let ranges = readings
            .get(from..to)
            .unwrap_or(&[])
            .iter()
            .map(|&v| {
                if v < scip::MIN_VALID {
                    max
                } else {
                    v as f32 / 1000.0
                }
            })
            .collect();
        laser::Scan {
            min_angle: self.angle(self.min_i),
            max_angle: self.angle(self.max_i),
            resolution: self.resolution as f32,
            max_range: max,
            ranges,
            intensity: vec![],
            id,
        }
    }

    /// Player's `Conf`, as `get_config` answers it.
    pub fn config(&self) -> laser::Config {
        laser::Config {
            min_angle: self.angle(self.min_i),
            max_angle: self.angle(self.max_i),
            resolution: self.resolution as f32,
            max_range: self.max_range as f32,
            range_res: 0.001,
            intensity: false,
            scanning_frequency: self.frequency as f32,
        }
    }
}

/// The urglaser driver.
pub struct UrgLaser {
    laser: Device,
    settings: Settings,
    pose: [f64; 3],
    angles: (f64, f64),
    line: Option<Line>,
    /// The URG's scan window and serial number, once it has answered.
    window: Option<(Window, u32)>,
    scan_id: u32,
    /// Requests that came before the URG answered.
    waiting: Vec<(Responder, bool)>,
}

impl Driver for UrgLaser {
    const NAME: &'static str = "urglaser";
    type Options = Options;
    const UNITS: &'static [(&'static str, Unit)] = &[
        (
            "pose",
            Unit::Tuple(&[Unit::Length, Unit::Length, Unit::Angle]),
        ),
        ("min_angle", Unit::Angle),
        ("max_angle", Unit::Angle),
    ];

    fn new(section: &Section, o: Options) -> Result<Self> {
        let baud = if URG_RATES.contains(&o.baud) {
            o.baud as u32
        } else {
            tracing::warn!(
                "ignoring invalid baud rate {}: using 115200 (19200, 57600 or 115200)",
                o.baud
            );
            115200
        };
        if o.min_angle > o.max_angle {
            tracing::warn!(
                "min_angle {:.1}° is beyond max_angle {:.1}°: the scan is one step",
                o.min_angle.to_degrees(),
                o.max_angle.to_degrees()
            );
        }
        Ok(UrgLaser {
            laser: section.provided_one(Interface::Laser, None)?,
            settings: Settings {
                port: o.port,
                serial: o.use_serial == 1,
                baud,
            },
            pose: o.pose,
            angles: (o.min_angle, o.max_angle),
            line: None,
            window: None,
            scan_id: 0,
            waiting: Vec::new(),
        })
    }

    fn setup(&mut self, ctx: &mut Ctx) -> Result<()> {
        ctx.set_ready(false);
        ctx.answer_always::<laser::GetGeom>(&self.laser, &self.geom())?;
        let line = device::spawn(self.settings.clone(), ctx.waker())
            .map_err(|e| NodeError::Driver(format!("starting the line thread: {e}").into()))?;
        tracing::info!(
            "laser initialising ({} over {})",
            self.settings.port.display(),
            if self.settings.serial {
                "RS-232"
            } else {
                "USB"
            }
        );
        self.line = Some(line);
        Ok(())
    }

    fn on_event(&mut self, ctx: &mut Ctx, event: Event) -> Result<()> {
        match event {
            Event::Wake => self.drain(ctx),
            Event::Request(r) if r.is::<laser::GetConfig>() || r.is::<laser::GetId>() => {
                let id = r.is::<laser::GetId>();
                match &self.window {
                    Some(w) => answer(r.responder, w, id),
                    // Answered once the URG has said what it measures.
                    None => self.waiting.push((r.responder, id)),
                }
                Ok(())
            }
            Event::Request(r) if r.is::<laser::SetConfig>() => {
                r.nack(
                    "urglaser does not change its scan (Player's driver refused set_config too)",
                );
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

fn answer(r: Responder, (w, serial): &(Window, u32), id: bool) {
    if id {
        r.reply(&laser::Id {
            serial_number: *serial,
        });
    } else {
        r.reply(&w.config());
    }
}

impl UrgLaser {
    fn geom(&self) -> laser::Geom {
        laser::Geom {
            pose: Pose3d::planar(self.pose[0], self.pose[1], self.pose[2]),
            size: Size3d {
                length: 0.05,
                width: 0.05,
                height: 0.0,
            },
        }
    }

    fn drain(&mut self, ctx: &mut Ctx) -> Result<()> {
        for u in self.line.updates_now() {
            match u {
                Update::Ready {
                    specs,
                    version,
                    baud,
                } => {
                    let w = Window::new(&specs, self.angles.0, self.angles.1);
                    let c = w.config();
                    tracing::info!(
                        "laser ready: {version}{}; {} ranges, {:.2}° to {:.2}°",
                        if baud > 0 {
                            format!(" at {baud} baud")
                        } else {
                            " over USB".into()
                        },
                        w.max_i - w.min_i,
                        c.min_angle.to_degrees(),
                        c.max_angle.to_degrees()
                    );
                    let known = (w, specs.serial);
                    for (r, id) in self.waiting.drain(..) {
                        answer(r, &known, id);
                    }
                    self.window = Some(known);
                    ctx.set_ready(true);
                }
                Update::Lost(why) => {
                    if ctx.is_ready() {
                        tracing::warn!("laser lost: {why}");
                    }
                    ctx.set_ready(false);
                }
                Update::Scan(readings) => {
                    if let Some((w, _)) = &self.window {
                        let scan = w.scan(&readings, self.scan_id);
                        self.scan_id = self.scan_id.wrapping_add(1);
                        ctx.publish(&self.laser, &scan)?;
                    }
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn specs() -> Specs {
        Specs {
            max_range_mm: 4095,
            first_step: 44,
            last_step: 725,
            ares: 1024,
            rpm: 600,
            serial: 1,
            firmware: 3,
        }
    }

    #[test]
    fn the_window_is_players() {
        // urglaser.cfg's ±115°: steps round(384 ∓ 327.1).
        let w = Window::new(&specs(), (-115f64).to_radians(), 115f64.to_radians());
        assert_eq!((w.min_i, w.max_i), (57, 711));
        let c = w.config();
        assert!((c.min_angle.to_degrees() + 114.96).abs() < 0.01, "{c:?}");
        assert!((c.max_angle.to_degrees() - 114.96).abs() < 0.01, "{c:?}");
        // The default ±120° is more than the URG-04LX measures.
        let w = Window::new(&specs(), (-120f64).to_radians(), 120f64.to_radians());
        assert_eq!((w.min_i, w.max_i), (44, 725));
    }

    #[test]
    fn a_scan_is_players_data() {
        let w = Window::new(&specs(), -0.01, 0.01);
        assert_eq!((w.min_i, w.max_i), (382, 386));
        let mut readings = vec![1000; 769];
        readings[383] = 1;
        readings[385] = 4095;
        let s = w.scan(&readings, 3);
        // max_i − min_i ranges, from min_i: Player's count.
        assert_eq!(s.ranges, vec![1.0, 4.095, 1.0, 4.095]);
        assert_eq!((s.id, s.max_range), (3, 4.095));
        assert!(s.intensity.is_empty());
    }
}
