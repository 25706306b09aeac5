//! Player's `readlog`: replays a Player text log as if its devices were live.
//!
//! ```text
//! driver ( name "readlog" filename "run.log" provides ["log:0" "laser:0" "position2d:0"]
//!          speed 1.0 autoplay 1 autorewind 0 )
//! ```
//!
//! | | |
//! |---|---|
//! | requires | none |
//! | provides | the logged devices, matched by robot port, interface and index; optionally one `log` |
//! | options | `filename` (required), `speed` (1.0), `autoplay` (1), `autorewind` (0) |
//!
//! # Behavior
//!
//! - The answers logged first (geometries, a ranger's configuration,
//!   particles) answer those requests to the replayed devices; other
//!   requests are refused, as Player's readlog refused them.
//! - Data lines are published at the pace of their timestamps divided by
//!   `speed`, each stamped with its logged time. readlog is its stack's
//!   clock, as Player's readlog replaced Player's clock: `sim/clock` follows
//!   the log, and amcl, the bridge and the rest run in the log's time.
//! - A line is replayed on the provided device of the same robot (port),
//!   interface and index; Player also matched the host, which Troupe's
//!   devices do not have. Lines of other devices are skipped, said once per
//!   device with a count.
//! - `log` requests: `set_read_state` plays and pauses, `get_state` says
//!   which, `rewind` goes back to the start. At the end, `autorewind 1`
//!   starts again; otherwise playback stops until a rewind and a play.
//! - A line that cannot be read is skipped: the first of each kind of
//!   problem is reported with the file and line, the rest counted and
//!   summed up at the end of each pass.

use std::collections::BTreeMap;
use std::io::{BufRead as _, Seek as _};
use std::path::PathBuf;
use std::time::{Duration, Instant};

use serde::Deserialize;
use troupe_msgs::{
    bumper, common, fiducial, ir, laser, localize, log, position2d, ranger, sonar, AnyMsg, Device,
    Interface,
};
use troupe_node::{Ctx, Driver, Event, NodeError, Result, Section, Switch, Unit};

use crate::text;

/// Options, by Player's names.
#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub struct Options {
    /// The log to read (required).
    pub filename: Option<PathBuf>,
    /// Playback speed: 2.0 is twice as fast as logged (default 1.0).
    pub speed: Option<f64>,
    /// Play from the start (default on).
    pub autoplay: Option<Switch>,
    /// Start again at the end (default off).
    pub autorewind: Option<Switch>,
}

/// How often playback looks for lines that are due (Player's readlog
/// looked every millisecond).
const POLL: Duration = Duration::from_millis(2);

/// Lines published per look at most, so that requests are answered in
/// between even at great speeds.
const BATCH: usize = 2000;

/// The readlog driver.
pub struct ReadLog {
    path: PathBuf,
    /// Opened at setup, as Player's readlog opened it (a plan may name a
    /// log that a writelog has yet to write).
    file: Option<std::io::BufReader<std::fs::File>>,
    line_no: u64,
    log: Option<Device>,
    devices: Vec<Device>,
    speed: f64,
    enabled: bool,
    autorewind: bool,
    /// When the last data line went out: wall instant and log time.
    anchor: Option<(Instant, f64)>,
    /// A data line read and not yet due.
    next: Option<(f64, Device, AnyMsg)>,
    at_end: bool,
    /// Problems met: the first's line, and how many; each said once, and
    /// summed up at the end of the first pass.
    problems: BTreeMap<String, (u64, u64)>,
    summarized: bool,
    /// Lines of devices not provided, by device.
    unmatched: BTreeMap<Device, u64>,
    /// The line being read (kept: one buffer for the whole log).
    buf: Vec<u8>,
    published: u64,
}

impl Driver for ReadLog {
    const NAME: &'static str = "readlog";
    type Options = Options;
    const UNITS: &'static [(&'static str, Unit)] = &[("filename", Unit::Path)];
    const CLOCK_SOURCE: bool = true;

    fn new(section: &Section, o: Options) -> Result<Self> {
        let bad = |what: String| NodeError::config(Self::NAME, what);
        let path = o
            .filename
            .ok_or_else(|| bad("must specify a log file to read from (`filename`)".into()))?;
        let speed = o.speed.unwrap_or(1.0);
        if !(speed.is_finite() && speed > 0.0) {
            return Err(bad(format!("speed {speed}: expected a factor above 0")));
        }
        let mut log = None;
        let mut devices = Vec::new();
        for s in section.provided() {
            if s.device.interface == Interface::Log {
                log = Some(s.device);
            } else {
                devices.push(s.device);
            }
        }
        Ok(ReadLog {
            path,
            file: None,
            line_no: 0,
            log,
            devices,
            speed,
            enabled: o.autoplay.is_none_or(Switch::on),
            autorewind: o.autorewind.is_some_and(Switch::on),
            anchor: None,
            next: None,
            at_end: false,
            problems: BTreeMap::new(),
            summarized: false,
            unmatched: BTreeMap::new(),
            buf: Vec::new(),
            published: 0,
        })
    }

    fn setup(&mut self, ctx: &mut Ctx) -> Result<()> {
        let file = std::fs::File::open(&self.path).map_err(|e| {
            NodeError::config(
                Self::NAME,
                format!("unable to open {}: {e}", self.path.display()),
            )
        })?;
        self.file = Some(std::io::BufReader::new(file));
        ctx.set_time(0.0)?;
        // The answers at the front are known before any client asks.
        self.read_next(ctx)?;
        self.set_playing(ctx, self.enabled);
        Ok(())
    }

    fn on_event(&mut self, ctx: &mut Ctx, event: Event) -> Result<()> {
        match event {
            Event::Tick => self.play(ctx),
            Event::Request(r) if Some(r.sample.device) == self.log => {
                if r.is::<log::SetReadState>() {
                    let on = r.decode::<log::SetReadState>()?.state;
                    tracing::info!("{} playback", if on { "start" } else { "stop" });
                    self.set_playing(ctx, on);
                    r.reply(&common::Ack);
                } else if r.is::<log::GetState>() {
                    r.reply(&log::State {
                        kind: log::TYPE_READ,
                        state: self.enabled,
                    });
                } else if r.is::<log::Rewind>() {
                    self.rewind(ctx)?;
                    r.reply(&common::Ack);
                } else {
                    let why = format!("readlog's log device does not handle `{}`", r.name);
                    r.nack(why);
                }
                Ok(())
            }
            Event::Request(r) => {
                let why = format!(
                    "the log {} holds no answer to `{}` for {}",
                    self.path.display(),
                    r.name,
                    r.sample.device
                );
                r.nack(why);
                Ok(())
            }
            Event::Command(c) => {
                tracing::debug!("a replayed device takes no commands; ignored `{}`", c.key);
                Ok(())
            }
            Event::Data(_) | Event::Reply(_) | Event::Wake => Ok(()),
        }
    }
}

impl ReadLog {
    fn set_playing(&mut self, ctx: &mut Ctx, on: bool) {
        self.enabled = on;
        // Resuming publishes the next line at once, as Player's did.
        self.anchor = None;
        ctx.set_tick(on.then_some(POLL));
    }

    fn rewind(&mut self, ctx: &mut Ctx) -> Result<()> {
        self.summarize();
        let Some(file) = self.file.as_mut() else {
            return Ok(());
        };
        if let Err(e) = file.seek(std::io::SeekFrom::Start(0)) {
            tracing::warn!("while rewinding {}: {e}; going on", self.path.display());
            return Ok(());
        }
        self.line_no = 0;
        self.next = None;
        self.anchor = None;
        self.at_end = false;
        ctx.set_time(0.0)?;
        tracing::debug!("log rewound");
        Ok(())
    }

    /// Publishes every line that is due.
    fn play(&mut self, ctx: &mut Ctx) -> Result<()> {
        for _ in 0..BATCH {
            if !self.enabled {
                return Ok(());
            }
            if self.next.is_none() {
                self.read_next(ctx)?;
            }
            let Some((t, _, _)) = &self.next else {
                // The end: start again, or stop.
                if !self.at_end {
                    self.at_end = true;
                    tracing::info!(
                        "reached the end of {} ({} messages replayed)",
                        self.path.display(),
                        self.published
                    );
                    self.summarize();
                }
                if self.autorewind {
                    self.rewind(ctx)?;
                    continue;
                }
                self.enabled = false;
                ctx.set_tick(None);
                return Ok(());
            };
            let t = *t;
            let now = Instant::now();
            let due = match self.anchor {
                None => now,
                Some((wall, logged)) => {
                    wall + Duration::from_secs_f64(((t - logged) / self.speed).max(0.0))
                }
            };
            if due > now {
                return Ok(());
            }
            let Some((t, dev, msg)) = self.next.take() else {
                return Ok(());
            };
            self.anchor = Some((due, t));
            ctx.set_time(t)?;
            ctx.publish_encoded(&dev, msg.encode(t))?;
            self.published += 1;
        }
        Ok(())
    }

    /// Reads lines until a data line for a provided device (kept in
    /// `next`) or the end; answers logged on the way answer requests.
    fn read_next(&mut self, ctx: &mut Ctx) -> Result<()> {
        let mut buf = std::mem::take(&mut self.buf);
        let found = self.read_into(ctx, &mut buf);
        self.buf = buf;
        found
    }

    /// [`ReadLog::read_next`], reading each line into `buf`.
    fn read_into(&mut self, ctx: &mut Ctx, buf: &mut Vec<u8>) -> Result<()> {
        loop {
            buf.clear();
            let Some(file) = self.file.as_mut() else {
                return Ok(());
            };
            match file.read_until(b'\n', buf) {
                Ok(0) => return Ok(()),
                Ok(_) => {}
                Err(e) => {
                    tracing::error!("cannot read {}: {e}", self.path.display());
                    return Ok(());
                }
            }
            self.line_no += 1;
            let text = String::from_utf8_lossy(buf);
            let line = match text::parse(&text) {
                Ok(Some(l)) => l,
                Ok(None) => continue,
                Err(e) => {
                    self.problem(e.to_string());
                    continue;
                }
            };
            let Some(dev) = self.devices.iter().copied().find(|d| {
                d.robot == line.robot && d.interface == line.interface && d.index == line.index
            }) else {
                let what = Device::new(line.robot, line.interface, line.index);
                let n = self.unmatched.entry(what).or_default();
                if *n == 0 {
                    tracing::info!(
                        "{}: {what} is not among the provided devices; its lines are skipped",
                        self.path.display()
                    );
                }
                *n += 1;
                continue;
            };
            let msg = match text::message(&line) {
                Ok(m) => m,
                Err(e) => {
                    self.problem(e.to_string());
                    continue;
                }
            };
            if answer(ctx, &dev, &msg)? {
                continue;
            }
            self.next = Some((line.time, dev, msg));
            return Ok(());
        }
    }

    fn problem(&mut self, what: String) {
        let line = self.line_no;
        let e = self.problems.entry(what.clone()).or_insert((line, 0));
        if e.1 == 0 {
            tracing::warn!(
                "{}:{line}: {what}; line skipped (more like it are counted)",
                self.path.display()
            );
        }
        e.1 += 1;
    }

    /// Says how many lines each problem cost, once, at the end of the first pass.
    fn summarize(&mut self) {
        if std::mem::replace(&mut self.summarized, true) {
            return;
        }
        for (what, &(first, n)) in &self.problems {
            if n > 1 {
                tracing::warn!(
                    "{}: {n} lines skipped for: {what} (the first at line {first})",
                    self.path.display()
                );
            }
        }
        for (dev, n) in &self.unmatched {
            tracing::info!(
                "{}: {n} lines of {dev} skipped (not provided)",
                self.path.display()
            );
        }
    }
}

/// Makes a logged answer (a geometry, a configuration, particles) the
/// answer to its request; false for data.
fn answer(ctx: &mut Ctx, dev: &Device, msg: &AnyMsg) -> Result<bool> {
    match msg {
        AnyMsg::LaserGeom(g) => ctx.answer_always::<laser::GetGeom>(dev, g),
        AnyMsg::RangerGeom(g) => ctx.answer_always::<ranger::GetGeom>(dev, g),
        AnyMsg::RangerConfig(c) => ctx.answer_always::<ranger::GetConfig>(dev, c),
        AnyMsg::Position2dGeom(g) => ctx.answer_always::<position2d::GetGeom>(dev, g),
        AnyMsg::SonarGeom(g) => ctx.answer_always::<sonar::GetGeom>(dev, g),
        AnyMsg::IrGeom(g) => ctx.answer_always::<ir::GetGeom>(dev, g),
        AnyMsg::BumperGeom(g) => ctx.answer_always::<bumper::GetGeom>(dev, g),
        AnyMsg::FiducialGeom(g) => ctx.answer_always::<fiducial::GetGeom>(dev, g),
        AnyMsg::LocalizeParticles(p) => ctx.answer_always::<localize::GetParticles>(dev, p),
        _ => return Ok(false),
    }?;
    Ok(true)
}
