//! An emulated SICK LMS200 on a pseudo-terminal.
//!
//! It plays the scanner's side of every exchange Player's driver has with
//! it: powers up at 9600 baud, ignores bytes sent at any other rate,
//! answers with an ACK byte and a reply telegram, switches rate after
//! acknowledging, keeps the variant and configuration Player writes (and
//! refuses a configuration outside installation mode, or a wrong password),
//! and streams 0xB0/0xB7 scan telegrams at the LMS200's own pace — a
//! 75 Hz mirror, interlaced at 0.5° and 0.25° — or the line's, whichever is
//! slower. Ranges come from a [`Scene`] (`troupe_geom`'s).

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use troupe_serial::{EmuLine, Framer, LineEvent, LineOptions};

use crate::telegram::{self, cmd, mode, Telegram, TelegramCodec, ACK_BYTE, NAK_BYTE};
use troupe_geom::Scene;

/// The type string the emulated scanner reports.
pub const KIND: &str = "LMS200;30106";

/// Counts for the log.
#[derive(Debug, Default, Clone, Copy)]
pub struct EmulatorStats {
    /// Requests answered.
    pub requests: u64,
    /// Scans sent.
    pub scans: u64,
    /// Requests refused (NACK) or not understood (NAK).
    pub refused: u64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    Idle,
    Config,
    Stream { first: u16, last: u16, part: bool },
}

/// The scanner's state: what a power cycle resets.
#[derive(Debug)]
struct Lms {
    baud: u32,
    mode: Mode,
    width: u16,
    res: u16,
    config: [u8; 32],
}

impl Lms {
    fn power_up() -> Lms {
        let mut config = [0u8; 32];
        // Blanking, sensitivity, availability, measuring mode, units…
        // Only bytes 4..7 (availability, intensity, units) matter to Player.
        config[6] = telegram::units_code(10);
        Lms {
            baud: 9600,
            mode: Mode::Idle,
            width: 180,
            res: 100,
            config,
        }
    }

    fn units(&self) -> u8 {
        self.config[6]
    }

    fn intensity(&self) -> bool {
        self.config[5] != 0
    }

    /// How often the mirror completes a scan at this resolution.
    fn scan_period(&self) -> Duration {
        let interlace = match self.res {
            25 => 4,
            50 => 2,
            _ => 1,
        };
        Duration::from_secs_f64(f64::from(interlace) / 75.0)
    }
}

/// Runs the emulated scanner until `stop` is set.
///
/// # Errors
///
/// When the pseudo-terminal cannot be opened or linked, or fails.
pub fn run(
    opts: &LineOptions,
    scene: &mut dyn Scene,
    stop: &AtomicBool,
) -> std::io::Result<EmulatorStats> {
    run_with(opts, scene, stop, || {})
}

/// [`run`], calling `linked` once the line is linked and the scanner is
/// powered up (a test waits for it before starting a driver).
///
/// # Errors
///
/// As [`run`].
pub fn run_with(
    opts: &LineOptions,
    scene: &mut dyn Scene,
    stop: &AtomicBool,
    linked: impl FnOnce(),
) -> std::io::Result<EmulatorStats> {
    let mut line = EmuLine::open(opts, "sicklms200")?;
    linked();
    let mut lms = Lms::power_up();
    let mut framer = Framer::new(TelegramCodec {
        addr: telegram::TO_DEVICE,
    });
    let mut stats = EmulatorStats::default();
    let start = Instant::now();
    let mut next_scan = Instant::now();
    let mut buf = [0u8; 1024];
    while !stop.load(Ordering::Relaxed) {
        let wait = match lms.mode {
            Mode::Stream { .. } => next_scan.saturating_duration_since(Instant::now()),
            _ => Duration::from_millis(100),
        };
        match line.recv(&mut buf, lms.baud, wait.min(Duration::from_millis(100)))? {
            LineEvent::Received(n) => {
                framer.push(&buf[..n]);
                let before = framer.stats.checksum + framer.stats.malformed;
                while let Some(t) = framer.next_frame() {
                    answer(&mut lms, &t, &mut line, &mut stats)?;
                }
                if framer.stats.checksum + framer.stats.malformed > before {
                    // The LMS200 answers a damaged telegram with a lone NAK.
                    stats.refused += 1;
                    line.send(&[NAK_BYTE], lms.baud)?;
                }
            }
            LineEvent::Replugged => {
                lms = Lms::power_up();
                framer.clear();
            }
            LineEvent::Idle | LineEvent::Unplugged => {}
        }
        if let Mode::Stream { first, last, part } = lms.mode {
            let now = Instant::now();
            if now >= next_scan && line.plugged() {
                let t = start.elapsed().as_secs_f64();
                let values = scan(&lms, scene, t, first, last);
                let bytes = if part {
                    telegram::encode_scan_part(first, last, &values, lms.units(), 0x10)
                } else {
                    telegram::encode_scan(&values, lms.units(), 0x10)
                };
                line.send(&bytes, lms.baud)?;
                stats.scans += 1;
                // The next scan goes out when the mirror has finished one
                // and the line is free.
                let mut due = next_scan + lms.scan_period();
                while due < now {
                    due += lms.scan_period();
                }
                next_scan = due.max(line.idle_at());
            }
        }
    }
    let _counts = line.counts_span().entered();
    tracing::info!(
        requests = stats.requests,
        scans = stats.scans,
        refused = stats.refused,
        "emulated sicklms200 stopped"
    );
    Ok(stats)
}

/// Values `first..=last` (1-based segments) of a scan at time `t`.
fn scan(lms: &Lms, scene: &mut dyn Scene, t: f64, first: u16, last: u16) -> Vec<u16> {
    let res = f64::from(lms.res) / 100.0;
    let half = f64::from(lms.width) / 2.0;
    let angles: Vec<f64> = (first..=last)
        .map(|s| (f64::from(s - 1) * res - half).to_radians())
        .collect();
    let unit_m = f64::from(telegram::units_mm(lms.units())) / 1000.0;
    scene
        .ranges(t, &angles)
        .into_iter()
        .map(|r| {
            // 8183 and above are the LMS200's error codes; out of reach reads 8183.
            let v = (r / unit_m).round().clamp(0.0, 8183.0) as u16;
            let flags = if lms.intensity() && v < 1000 {
                1 << 13
            } else {
                0
            };
            v | flags
        })
        .collect()
}

fn answer(
    lms: &mut Lms,
    t: &Telegram,
    line: &mut EmuLine,
    stats: &mut EmulatorStats,
) -> std::io::Result<()> {
    stats.requests += 1;
    let data = t.request_data();
    let baud = lms.baud;
    let send = |line: &mut EmuLine, cmd: u8, payload: &[u8]| {
        let mut bytes = vec![ACK_BYTE];
        bytes.extend(telegram::reply(cmd, payload, 0x10));
        line.send(&bytes, baud)
    };
    let refuse = |line: &mut EmuLine, stats: &mut EmulatorStats| {
        stats.refused += 1;
        let mut bytes = vec![ACK_BYTE];
        bytes.extend(telegram::reply(cmd::NACK, &[], 0x10));
        line.send(&bytes, baud)
    };
    match (t.cmd(), data) {
        (cmd::MODE, [m, rest @ ..]) => {
            let reply = cmd::MODE | cmd::REPLY;
            match *m {
                mode::CONFIG => {
                    let ok = rest.len() == 8
                        && rest[..5] == *b"SICK_"
                        && rest[5..] == KIND.as_bytes()[..3];
                    if ok {
                        lms.mode = Mode::Config;
                    }
                    send(line, reply, &[if ok { 0 } else { 1 }])
                }
                mode::STOP => {
                    lms.mode = Mode::Idle;
                    send(line, reply, &[0])
                }
                mode::CONTINUOUS => {
                    let last = lms.width * 100 / lms.res + 1;
                    lms.mode = Mode::Stream {
                        first: 1,
                        last,
                        part: false,
                    };
                    send(line, reply, &[0])
                }
                mode::CONTINUOUS_PART if rest.len() == 4 => {
                    let first = u16::from_le_bytes([rest[0], rest[1]]);
                    let last = u16::from_le_bytes([rest[2], rest[3]]);
                    let top = lms.width * 100 / lms.res + 1;
                    if first == 0 || first > last || last > top {
                        return send(line, reply, &[2]);
                    }
                    lms.mode = Mode::Stream {
                        first,
                        last,
                        part: true,
                    };
                    send(line, reply, &[0])
                }
                m => match telegram::mode_baud(m) {
                    Some(new) => {
                        send(line, reply, &[0])?;
                        lms.baud = new;
                        Ok(())
                    }
                    None => refuse(line, stats),
                },
            }
        }
        (cmd::MODE, []) => refuse(line, stats),
        (cmd::TYPE, _) => send(line, cmd::TYPE | cmd::REPLY, KIND.as_bytes()),
        (cmd::STATUS, _) => {
            let mut status = [0u8; 152];
            status[..7].copy_from_slice(b"V02.10 ");
            status[106..108].copy_from_slice(&lms.width.to_le_bytes());
            status[108..110].copy_from_slice(&lms.res.to_le_bytes());
            send(line, cmd::STATUS | cmd::REPLY, &status)
        }
        (cmd::VARIANT, [w0, w1, r0, r1]) => {
            let (w, r) = (
                u16::from_le_bytes([*w0, *w1]),
                u16::from_le_bytes([*r0, *r1]),
            );
            let ok = matches!(
                (w, r),
                (100, 25) | (100, 50) | (100, 100) | (180, 50) | (180, 100)
            );
            if ok {
                lms.width = w;
                lms.res = r;
            }
            send(
                line,
                cmd::VARIANT | cmd::REPLY,
                &[u8::from(ok), *w0, *w1, *r0, *r1],
            )
        }
        (cmd::GET_CONFIG, _) => {
            let config = lms.config;
            send(line, cmd::GET_CONFIG | cmd::REPLY, &config)
        }
        (cmd::SET_CONFIG, d) if lms.mode == Mode::Config && d.len() >= 7 => {
            let n = d.len().min(32);
            lms.config[..n].copy_from_slice(&d[..n]);
            let mut reply = vec![1];
            reply.extend_from_slice(&lms.config);
            send(line, cmd::SET_CONFIG | cmd::REPLY, &reply)
        }
        _ => refuse(line, stats),
    }
}
