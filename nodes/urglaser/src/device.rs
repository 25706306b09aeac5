//! The driver's side of the line: finds the URG, learns what it measures
//! and asks it for scans, one after another, on a thread of its own.
//!
//! The sequence is Player's `urg_laser`:
//! - **RS-232** (`use_serial 1`): at 19200, 57600 and 115200 baud in turn,
//!   ask the URG (SCIP 1.1's `S`) to switch to the wanted rate until one
//!   answers; then speak SCIP 1.1 — Player's driver never switches to 2.0
//!   on a serial line.
//! - **USB** (`use_serial 0`): ask `V`; a SCIP 1.1 URG with firmware 3 or
//!   later is switched to SCIP 2.0 (`SCIP2.0`, then `BM` to light the
//!   laser); one already in SCIP 2.0 answers `VV`.
//! - Its specifications from `V` (SCIP 1.1) or `PP` and `VV` (2.0); then a
//!   scan request (`G00076801` / `GD0000076801`: every step, one step per
//!   value) after another.
//!
//! Any failure — no answer, a refusal, a lost line, scans that stop — ends
//! the session: the driver is told, waits, and starts over.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::mpsc::{Receiver, TryRecvError};
use std::sync::Arc;
use std::time::{Duration, Instant};

use troupe_node::Waker;
use troupe_serial::{end_session, run_sessions, LineThread, Link, Reports, SessionError};

use crate::scip::{self, Response, ResponseCodec, Specs, Version};

/// How long to wait between two connection attempts.
pub const RECONNECT_DELAY: Duration = Duration::from_secs(2);
/// The rates Player's driver tries, in its order.
pub const SEARCH_RATES: [u32; 3] = [19200, 57600, 115200];
/// How long a baud-rate change may take to be answered at one rate. Player
/// waits 100 ms; a loaded machine's pseudo-terminal needs more.
const BAUD_PATIENCE: Duration = Duration::from_millis(500);
/// How long any other request may take, beyond the line time of its answer.
const PATIENCE: Duration = Duration::from_secs(1);
/// Tries of each request before the URG counts as not answering.
const TRIES: u32 = 3;
/// Scan requests in a row that may go unanswered before the URG counts as lost.
const MISSES: u32 = 3;

/// How to reach the URG.
#[derive(Debug, Clone)]
pub struct Settings {
    /// The serial or USB (CDC-ACM) device.
    pub port: PathBuf,
    /// Over RS-232 (search the rate, switch to `baud`, SCIP 1.1) or USB.
    pub serial: bool,
    /// The rate to switch to over RS-232.
    pub baud: u32,
}

/// What the device thread tells the driver.
#[derive(Debug)]
pub enum Update {
    /// Connected and scanning.
    Ready {
        /// What the URG said about itself.
        specs: Specs,
        /// The protocol spoken.
        version: Version,
        /// The line's rate (0 over USB).
        baud: u32,
    },
    /// A scan's readings, steps 0 to 768 (mm, or error codes below 20).
    Scan(Vec<u32>),
    /// The session ended; the thread retries after [`RECONNECT_DELAY`].
    Lost(String),
}

/// What the driver asks of the device thread.
#[derive(Debug)]
pub enum Order {
    /// Stop scanning (SCIP 2.0: put the laser out) and end.
    Stop,
}

#[derive(Debug)]
enum Fail {
    NoReply(String),
    Refused(String),
    Garbled(String),
    Specs(scip::SpecsError),
}

impl std::fmt::Display for Fail {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Fail::NoReply(what) => write!(f, "no reply to {what}"),
            Fail::Refused(what) => write!(f, "the URG refused {what}"),
            Fail::Garbled(what) => write!(f, "unreadable {what}"),
            Fail::Specs(e) => write!(f, "unreadable version or parameters: {e}"),
        }
    }
}

type Error = SessionError<Fail>;

fn fail<T>(f: Fail) -> Result<T, Error> {
    Err(SessionError::Device(f))
}

/// The line thread, as the driver holds it.
pub type Line = LineThread<Order, Update>;

/// Starts the line thread.
///
/// # Errors
///
/// When the thread cannot be started.
pub fn spawn(settings: Settings, waker: Waker) -> std::io::Result<Line> {
    LineThread::spawn(
        "urglaser line",
        move || waker.wake(),
        move |orders, reports, abort| run(settings, &reports, &orders, abort),
    )
}

/// Counts kept across sessions.
#[derive(Debug, Default, Clone, Copy)]
struct Counts {
    sessions: u64,
    scans: u64,
    bad_scans: u64,
}

fn run(
    mut settings: Settings,
    reports: &Reports<Update>,
    orders: &Receiver<Order>,
    abort: Arc<AtomicBool>,
) {
    let send = |u: Update| reports.send(u);
    let mut counts = Counts::default();
    let session = |settings: &mut Settings| {
        counts.sessions += 1;
        let port = settings.port.clone();
        let first_rate = if settings.serial {
            SEARCH_RATES[0]
        } else {
            settings.baud
        };
        let outcome = Link::session(&port, first_rate, ResponseCodec, abort.clone(), |link| {
            Session {
                settings,
                link,
                orders,
                send: &send,
                counts: &mut counts,
            }
            .run()
        });
        let _counts =
            tracing::warn_span!("laser", scans = counts.scans, bad_scans = counts.bad_scans)
                .entered();
        end_session(
            "laser",
            &port,
            counts.sessions,
            outcome,
            RECONNECT_DELAY,
            |why| send(Update::Lost(why)),
        )
    };
    run_sessions(&mut settings, orders, RECONNECT_DELAY, session, |_, o| {
        !matches!(o, Order::Stop)
    });
}

struct Session<'a, F: Fn(Update)> {
    settings: &'a Settings,
    link: &'a mut Link<ResponseCodec>,
    orders: &'a Receiver<Order>,
    send: &'a F,
    counts: &'a mut Counts,
}

impl<F: Fn(Update)> Session<'_, F> {
    fn run(&mut self) -> Result<(), Error> {
        let (version, baud) = if self.settings.serial {
            (Version::Scip1, self.switch_rate()?)
        } else {
            (self.choose_version()?, 0)
        };
        let specs = match version {
            // No checksums: a reply that does not parse is asked again.
            Version::Scip1 => self.ask(b"V", "the version request (V)", 200, |r| {
                scip::specs_1(r).map_err(Fail::Specs)
            })?,
            Version::Scip2 => {
                let pp = self.ask_2(b"PP", "the parameter request (PP)")?;
                let vv = self.ask_2(b"VV", "the version request (VV)")?;
                scip::specs_2(&pp, &vv).map_err(|e| SessionError::Device(Fail::Specs(e)))?
            }
        };
        tracing::info!(
            "URG firmware {}, serial {}: {}–{} mm, steps {}–{}, {} rpm; {version}",
            specs.firmware,
            specs.serial,
            scip::MIN_VALID,
            specs.max_range_mm,
            specs.first_step,
            specs.last_step,
            specs.rpm
        );
        (self.send)(Update::Ready {
            specs: specs.clone(),
            version,
            baud,
        });
        self.scan(version, &specs)
    }

    /// RS-232: Player's `ChangeBaud` at each search rate until the URG
    /// answers; the port follows it to the wanted rate.
    fn switch_rate(&mut self) -> Result<u32, Error> {
        let want = self.settings.baud;
        let command = format!("S{want:06}0000000");
        for rate in SEARCH_RATES {
            self.link.port.set_baud(rate)?;
            tracing::debug!("trying {rate} baud");
            match self.transact(command.as_bytes(), BAUD_PATIENCE)? {
                Some(r) if r.ok_1() => {
                    self.link.port.set_baud(want)?;
                    tracing::info!("laser answered at {rate} baud; switched to {want}");
                    return Ok(want);
                }
                // A digit: the URG cannot take that rate.
                Some(r) if matches!(r.status(), [b'1'..=b'9']) => {
                    return fail(Fail::Refused(format!(
                        "{want} baud (status {})",
                        String::from_utf8_lossy(r.status())
                    )))
                }
                // Damaged: it may have switched already, and answers at
                // the new rate further on.
                Some(_) | None => continue,
            }
        }
        fail(Fail::NoReply(format!(
            "a baud rate change at {} baud (is the URG on and on this port?)",
            SEARCH_RATES.map(|r| r.to_string()).join(", ")
        )))
    }

    /// USB: Player's `QuerySCIPVersion`. A URG in SCIP 1.1 with firmware 3
    /// or later is switched to SCIP 2.0 and its laser lit; one that answers
    /// `V` in SCIP 2.0 (an earlier session switched it) is lit.
    fn choose_version(&mut self) -> Result<Version, Error> {
        let firmware = self.ask(b"V", "the version request (V)", 200, |r| {
            if r.ok_1() {
                let s = scip::specs_1(r).map_err(Fail::Specs)?;
                Ok(Some(s.firmware))
            } else if r.status_2().is_some() {
                Ok(None)
            } else {
                Err(Fail::Garbled("status of the version request (V)".into()))
            }
        })?;
        if let Some(firmware) = firmware {
            if firmware < 3 {
                return Ok(Version::Scip1);
            }
            // A retry after a lost answer finds it switched already.
            self.ask(b"SCIP2.0", "the switch to SCIP 2.0", 16, |r| {
                if r.ok_1() || r.status_2().is_some() {
                    Ok(())
                } else {
                    Err(Fail::Garbled("status of the switch to SCIP 2.0".into()))
                }
            })?;
        }
        // 02: the laser was on already.
        self.ask(b"BM", "laser on (BM)", 16, |r| match r.status_2() {
            Some(b"00" | b"02") => Ok(()),
            Some(s) => Err(Fail::Refused(format!(
                "laser on (BM): status {}",
                String::from_utf8_lossy(s)
            ))),
            None => Err(Fail::Garbled("status of laser on (BM)".into())),
        })?;
        Ok(Version::Scip2)
    }

    /// Sends `command` and waits up to `timeout` for its answer, skipping
    /// responses to other commands (a scan still on the line).
    fn transact(&mut self, command: &[u8], timeout: Duration) -> Result<Option<Response>, Error> {
        self.link.flush();
        let mut line = command.to_vec();
        line.push(b'\n');
        self.link.send(&line)?;
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.link.read(left)? {
                Some(r) if r.answers(command) => return Ok(Some(r)),
                Some(_) => continue,
                None => return Ok(None),
            }
        }
    }

    /// Asks `command` (`what`, answered in about `bytes` bytes) until
    /// `read` makes something of the answer: [`TRIES`] times, a lost or
    /// damaged answer asked again; a refusal ends the session.
    fn ask<T>(
        &mut self,
        command: &[u8],
        what: &str,
        bytes: usize,
        read: impl Fn(&Response) -> Result<T, Fail>,
    ) -> Result<T, Error> {
        let timeout = PATIENCE + self.line_time(bytes);
        let mut last = Fail::NoReply(what.into());
        for _ in 0..TRIES {
            match self.transact(command, timeout)? {
                None => last = Fail::NoReply(what.into()),
                Some(r) => match read(&r) {
                    Ok(t) => return Ok(t),
                    Err(Fail::Garbled(why)) => {
                        tracing::debug!("damaged answer to {what}: {why}");
                        last = Fail::Garbled(why);
                    }
                    Err(f) => return fail(f),
                },
            }
        }
        fail(last)
    }

    /// A SCIP 2.0 command that must answer status 00 with intact lines.
    fn ask_2(&mut self, command: &[u8], what: &str) -> Result<Response, Error> {
        self.ask(command, what, 400, |r| match r.status_2() {
            Some(b"00") if r.body().iter().all(|l| scip::param(l).is_some()) => Ok(r.clone()),
            Some(b"00") | None => Err(Fail::Garbled(format!("answer to {what}"))),
            Some(s) => Err(Fail::Refused(format!(
                "{what}: status {}",
                String::from_utf8_lossy(s)
            ))),
        })
    }

    /// How long `n` bytes take on the line (nothing, over USB).
    fn line_time(&self, n: usize) -> Duration {
        if self.settings.serial {
            troupe_serial::Pacer::line_time(n, self.link.port.baud())
        } else {
            Duration::ZERO
        }
    }

    fn scan(&mut self, version: Version, specs: &Specs) -> Result<(), Error> {
        let command = scip::scan_command(version);
        let count = usize::from(scip::STEPS);
        let width = match version {
            Version::Scip1 => 2,
            Version::Scip2 => 3,
        };
        // A scan: the values, a line feed (and a sum) per 64 characters, the header.
        let bytes = count * width * 66 / 64 + 32;
        let period = Duration::from_secs_f64(60.0 / f64::from(specs.rpm.max(1)));
        let timeout = PATIENCE + 2 * period + self.line_time(bytes);
        let mut misses = 0;
        loop {
            match self.orders.try_recv() {
                Ok(Order::Stop) | Err(TryRecvError::Disconnected) => {
                    self.shut_down(version);
                    return Err(Error::Stopped);
                }
                Err(TryRecvError::Empty) => {}
            }
            let answer = match self.transact(command, timeout) {
                Err(SessionError::Stopped) => {
                    self.shut_down(version);
                    return Err(Error::Stopped);
                }
                other => other?,
            };
            let Some(r) = answer else {
                misses += 1;
                tracing::debug!(misses, "no answer to a scan request");
                if misses >= MISSES {
                    return fail(Fail::NoReply(format!("{MISSES} scan requests in a row")));
                }
                continue;
            };
            misses = 0;
            match scip::decode_scan(&r, version, count) {
                Ok(values) => {
                    self.counts.scans += 1;
                    (self.send)(Update::Scan(values));
                }
                Err(scip::ScanError::Status(s)) if self.counts.scans == 0 => {
                    return fail(Fail::Refused(format!("scans (status {s:?})")));
                }
                Err(e) => {
                    self.counts.bad_scans += 1;
                    tracing::warn!(bad_scans = self.counts.bad_scans, "scan dropped: {e}");
                }
            }
        }
    }

    /// SCIP 2.0: put the laser out (`QT`), as the URG's own tools do;
    /// SCIP 1.1 has nothing to stop.
    fn shut_down(&mut self, version: Version) {
        self.link.closing();
        if version == Version::Scip2 {
            match self.transact(b"QT", Duration::from_millis(300)) {
                Ok(Some(r)) if r.status_2() == Some(b"00") => {}
                Ok(_) => tracing::warn!("no answer to laser off (QT)"),
                Err(e) => tracing::warn!("cannot put the laser out: {e}"),
            }
        }
        tracing::info!("laser stopped");
    }
}
