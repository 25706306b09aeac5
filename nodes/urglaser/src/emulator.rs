//! An emulated Hokuyo URG-04LX on a pseudo-terminal.
//!
//! It plays the scanner's side of every exchange Player's driver has with
//! it, in both protocols:
//! - it powers up speaking SCIP 1.1 at 19200 baud, with firmware 3 (so it
//!   can be switched to SCIP 2.0), and ignores bytes sent at another rate —
//!   unless it is on USB (`usb`), where there is no rate;
//! - SCIP 1.1: `V` (version and specifications), `S` (rate change, answered
//!   at the old rate), `G` (a scan), `SCIP2.0`;
//! - SCIP 2.0: `VV`, `PP`, `BM` and `QT` (laser on and off), `RS`, `SS`,
//!   `GD`, with their checksums;
//! - its mirror turns at 600 rpm: a scan request is answered when the scan
//!   under way is done, and the answer takes the line's time (at 115200
//!   baud a SCIP 1.1 scan is 1.6 kB, 0.14 s).
//!
//! Ranges come from a [`Scene`]: beyond reach (4.095 m in SCIP 1.1, 5.6 m
//! in 2.0) reads error code 1, as do the steps outside 44–725.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use troupe_geom::Scene;
use troupe_serial::{EmuLine, Framer, LineEvent, LineOptions};

use crate::scip::{self, CommandCodec, Response, Version};

/// The serial number the emulated URG reports (`SERI:H0508486`).
pub const SERIAL: u32 = 508_486;
/// First and last step the URG-04LX measures.
pub const MEASURED: (u16, u16) = (44, 725);
/// The mirror's speed.
pub const RPM: u32 = 600;
/// What a USB full-speed (12 Mbit/s) line carries, as a baud rate for
/// pacing (10 bits a byte).
const USB_PACE: u32 = 12_000_000;
/// The error code read where nothing echoes.
const NO_ECHO: u32 = 1;

/// How the emulated URG is set up.
#[derive(Debug, Clone)]
pub struct EmulatorOptions {
    /// The line.
    pub line: LineOptions,
    /// On USB (CDC-ACM): any baud rate reaches it, and it answers at USB speed.
    pub usb: bool,
}

/// Counts for the log.
#[derive(Debug, Default, Clone, Copy)]
pub struct EmulatorStats {
    /// Commands answered.
    pub commands: u64,
    /// Scans sent.
    pub scans: u64,
    /// Commands refused or not understood.
    pub refused: u64,
}

/// The scanner's state: what a power cycle resets.
#[derive(Debug)]
struct Urg {
    baud: u32,
    version: Version,
    laser: bool,
    powered: Instant,
}

impl Urg {
    fn power_up() -> Urg {
        Urg {
            baud: 19200,
            version: Version::Scip1,
            laser: true,
            powered: Instant::now(),
        }
    }

    fn max_mm(&self) -> u32 {
        match self.version {
            Version::Scip1 => 4095,
            Version::Scip2 => 5600,
        }
    }

    /// The rates it reads and sends at: on USB the line's rate means
    /// nothing (0 reads at any rate) and bytes go at USB's speed.
    fn rates(&self, usb: bool) -> (u32, u32) {
        if usb {
            (0, USB_PACE)
        } else {
            (self.baud, self.baud)
        }
    }

    /// When the scan under way at `now` is done.
    fn scan_done(&self, now: Instant) -> Instant {
        let period = Duration::from_secs_f64(60.0 / f64::from(RPM));
        let since = now.saturating_duration_since(self.powered);
        let n = since.as_nanos() / period.as_nanos() + 1;
        self.powered + period * u32::try_from(n).unwrap_or(u32::MAX)
    }
}

/// A scan asked for: its echo and steps, answered when `due`.
#[derive(Debug)]
struct Pending {
    echo: Vec<u8>,
    version: Version,
    first: u16,
    last: u16,
    cluster: u16,
    due: Instant,
}

/// Runs the emulated URG until `stop` is set, calling `linked` once the
/// line is linked (a test waits for it before starting a driver).
///
/// # Errors
///
/// When the pseudo-terminal cannot be opened or linked, or fails.
pub fn run_with(
    opts: &EmulatorOptions,
    scene: &mut dyn Scene,
    stop: &AtomicBool,
    linked: impl FnOnce(),
) -> std::io::Result<EmulatorStats> {
    let mut line = EmuLine::open(&opts.line, "urglaser")?;
    linked();
    let mut urg = Urg::power_up();
    let mut framer = Framer::new(CommandCodec);
    let mut stats = EmulatorStats::default();
    let mut pending: Option<Pending> = None;
    let mut buf = [0u8; 256];
    let start = Instant::now();
    while !stop.load(Ordering::Relaxed) {
        let wait = pending
            .as_ref()
            .map_or(Duration::from_millis(100), |p| {
                p.due.saturating_duration_since(Instant::now())
            })
            .min(Duration::from_millis(100));
        let (rx, tx) = urg.rates(opts.usb);
        match line.recv(&mut buf, rx, wait)? {
            LineEvent::Received(n) => {
                framer.push(&buf[..n]);
                while let Some(command) = framer.next_frame() {
                    stats.commands += 1;
                    answer(&mut urg, &command, tx, &mut line, &mut pending, &mut stats)?;
                }
            }
            LineEvent::Replugged => {
                urg = Urg::power_up();
                framer.clear();
                pending = None;
            }
            LineEvent::Idle | LineEvent::Unplugged => {}
        }
        let done = if line.plugged() {
            pending.take_if(|p| Instant::now() >= p.due)
        } else {
            None
        };
        if let Some(p) = done {
            let t = p.due.saturating_duration_since(start).as_secs_f64();
            let values = measure(&urg, scene, t, &p);
            let ms = p.due.saturating_duration_since(urg.powered).as_millis();
            let r = scip::encode_scan(&p.echo, p.version, &values, ms as u32);
            // At the rate in force now: a rate change may have come between.
            line.send(&r.to_bytes(), urg.rates(opts.usb).1)?;
            stats.scans += 1;
        }
    }
    let _counts = line.counts_span().entered();
    tracing::info!(
        commands = stats.commands,
        scans = stats.scans,
        refused = stats.refused,
        "emulated urglaser stopped"
    );
    Ok(stats)
}

/// The readings of steps `first..=last`, `cluster` steps to a value (the
/// nearest of them), as the scene is at time `t`.
fn measure(urg: &Urg, scene: &mut dyn Scene, t: f64, p: &Pending) -> Vec<u32> {
    let step = std::f64::consts::TAU / f64::from(scip::ARES);
    let steps: Vec<u16> = (p.first..=p.last).collect();
    let angles: Vec<f64> = steps
        .iter()
        .map(|&s| (f64::from(s) - f64::from(scip::FRONT)) * step)
        .collect();
    let ranges = scene.ranges(t, &angles);
    let reading = |(&s, &r): (&u16, &f64)| -> u32 {
        let mm = (r * 1000.0).round();
        if s < MEASURED.0 || s > MEASURED.1 || !mm.is_finite() || mm > f64::from(urg.max_mm()) {
            NO_ECHO
        } else {
            (mm as u32).max(scip::MIN_VALID)
        }
    };
    let values: Vec<u32> = steps.iter().zip(&ranges).map(reading).collect();
    values
        .chunks(usize::from(p.cluster.max(1)))
        .map(|c| {
            c.iter()
                .copied()
                .filter(|&v| v >= scip::MIN_VALID)
                .min()
                .unwrap_or(c[0])
        })
        .collect()
}

/// Digits of `s` as a number, or `None`.
fn digits(s: &[u8]) -> Option<u32> {
    if s.is_empty() || !s.iter().all(u8::is_ascii_digit) {
        return None;
    }
    std::str::from_utf8(s).ok()?.parse().ok()
}

/// The rates a URG-04LX takes that a serial port here can be set to.
const RATES: [u32; 5] = [19200, 38400, 57600, 115200, 500000];

fn answer(
    urg: &mut Urg,
    command: &[u8],
    tx: u32,
    line: &mut EmuLine,
    pending: &mut Option<Pending>,
    stats: &mut EmulatorStats,
) -> std::io::Result<()> {
    let version = urg.version;
    let reply = |status: &[u8], body: Vec<Vec<u8>>, line: &mut EmuLine| {
        let status = match version {
            Version::Scip1 => status.to_vec(),
            Version::Scip2 => scip::with_sum(status),
        };
        let mut lines = vec![command.to_vec(), status];
        lines.extend(body);
        line.send(&Response { lines }.to_bytes(), tx)
    };
    let text = |l: &str| l.as_bytes().to_vec();
    match (urg.version, command) {
        (Version::Scip1, b"V") => reply(
            b"0",
            vec![
                text("VEND:Hokuyo Automatic Co.,Ltd."),
                text("PROD:SOKUIKI Sensor URG-04LX"),
                text("FIRM:3.1.04,07/08/02(20-4095[mm],240[deg],44-725[step],600[rpm])"),
                text("PROT:SCIP 1.1"),
                text(&format!("SERI:H{SERIAL:07}")),
            ],
            line,
        ),
        (Version::Scip1, [b'S', rate @ ..]) if rate.len() == 13 => {
            match digits(&rate[..6]).filter(|r| RATES.contains(r)) {
                Some(r) => {
                    // Answered at the old rate, then switched.
                    reply(b"0", vec![], line)?;
                    urg.baud = r;
                    Ok(())
                }
                None => {
                    stats.refused += 1;
                    reply(b"1", vec![], line)
                }
            }
        }
        (Version::Scip1, b"SCIP2.0") => {
            reply(b"0", vec![], line)?;
            urg.version = Version::Scip2;
            urg.laser = false;
            Ok(())
        }
        (Version::Scip1, [b'G', args @ ..]) if args.len() == 8 => {
            let (a, b, c) = (digits(&args[..3]), digits(&args[3..6]), digits(&args[6..]));
            scan_request(urg, command, a, b, c, pending, |status| {
                stats.refused += 1;
                reply(status, vec![], line)
            })
        }
        (Version::Scip2, b"VV") => reply(
            b"00",
            vec![
                scip::param_line("VEND", "Hokuyo Automatic Co.,Ltd."),
                scip::param_line("PROD", "SOKUIKI Sensor URG-04LX"),
                scip::param_line("FIRM", "3.4.03(17/Dec./2007)"),
                scip::param_line("PROT", "SCIP 2.0"),
                scip::param_line("SERI", &format!("H{SERIAL:07}")),
            ],
            line,
        ),
        (Version::Scip2, b"PP") => reply(
            b"00",
            vec![
                scip::param_line("MODL", "URG-04LX(Hokuyo Automatic Co.,Ltd.)"),
                scip::param_line("DMIN", "20"),
                scip::param_line("DMAX", "5600"),
                scip::param_line("ARES", &scip::ARES.to_string()),
                scip::param_line("AMIN", &MEASURED.0.to_string()),
                scip::param_line("AMAX", &MEASURED.1.to_string()),
                scip::param_line("AFRT", &scip::FRONT.to_string()),
                scip::param_line("SCAN", &RPM.to_string()),
            ],
            line,
        ),
        (Version::Scip2, b"BM") => {
            let was = std::mem::replace(&mut urg.laser, true);
            reply(if was { b"02" } else { b"00" }, vec![], line)
        }
        (Version::Scip2, b"QT" | b"RS") => {
            urg.laser = false;
            *pending = None;
            reply(b"00", vec![], line)
        }
        (Version::Scip2, [b'S', b'S', rate @ ..]) if rate.len() == 6 => {
            match digits(rate).filter(|r| RATES.contains(r)) {
                Some(r) if r == urg.baud => reply(b"03", vec![], line),
                Some(r) => {
                    reply(b"00", vec![], line)?;
                    urg.baud = r;
                    Ok(())
                }
                None => {
                    stats.refused += 1;
                    reply(b"01", vec![], line)
                }
            }
        }
        (Version::Scip2, [b'G', b'D', args @ ..]) if args.len() == 10 => {
            if !urg.laser {
                stats.refused += 1;
                return reply(b"10", vec![], line);
            }
            let (a, b, c) = (digits(&args[..4]), digits(&args[4..8]), digits(&args[8..]));
            scan_request(urg, command, a, b, c, pending, |status| {
                stats.refused += 1;
                let two = [b'0', status[0]];
                reply(&two, vec![], line)
            })
        }
        (Version::Scip1, _) => {
            stats.refused += 1;
            reply(b"E", vec![], line)
        }
        (Version::Scip2, _) => {
            stats.refused += 1;
            reply(b"0E", vec![], line)
        }
    }
}

/// A scan request from `first` to `last` in clusters of `cluster` steps:
/// pending until the mirror's scan is done, or refused with status 1–4
/// (start, end, cluster unreadable; end before start or beyond the scan).
fn scan_request(
    urg: &Urg,
    command: &[u8],
    first: Option<u32>,
    last: Option<u32>,
    cluster: Option<u32>,
    pending: &mut Option<Pending>,
    refuse: impl FnOnce(&[u8]) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let top = u32::from(scip::STEPS) - 1;
    let (Some(first), Some(last), Some(cluster)) = (first, last, cluster) else {
        return refuse(b"1");
    };
    if last < first || last > top {
        return refuse(b"4");
    }
    let narrow = |v: u32| u16::try_from(v).unwrap_or(u16::MAX);
    *pending = Some(Pending {
        echo: command.to_vec(),
        version: urg.version,
        first: narrow(first),
        last: narrow(last),
        cluster: narrow(cluster.max(1)),
        due: urg.scan_done(Instant::now()),
    });
    Ok(())
}
