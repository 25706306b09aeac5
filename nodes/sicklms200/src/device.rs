//! The driver's side of the line: connects to the scanner, configures it
//! and streams scans, on a thread of its own.
//!
//! The sequence is Player's `MainSetup`/`Main`: open the port; at each
//! `connect_rate` in turn ask the scanner to stop streaming until one
//! answers; switch it and the port to `transfer_rate`; read its type; enter
//! configuration mode with the password `SICK_` + the type's first three
//! letters; set the variant (width, resolution) and the configuration
//! (units, intensity, availability) only when they differ; ask for
//! continuous scans. Any failure — no answer, a refusal, a lost line, scans
//! that stop — ends the session: the driver is told, waits, and starts over.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::mpsc::{Receiver, TryRecvError};
use std::sync::Arc;
use std::time::{Duration, Instant};

use troupe_node::Waker;
use troupe_serial::{
    end_session, run_sessions, LineThread, Link, LinkError, Reports, SessionError,
};

use crate::telegram::{self, cmd, mode, RawScan, Telegram, TelegramCodec};

/// Player's retries for each request.
///
/// Each request waits for its reply as long as Player waits for the reply's
/// header (1 s to stop streaming, 2.5 s for configuration mode, 10 s for a
/// configuration written to flash, 2 s for the rest) — not Player's 25 s for
/// a whole status or configuration telegram, which only made a corrupted
/// reply cost 25 s.
const TRIES: u32 = 3;
/// How long to wait between two connection attempts.
pub const RECONNECT_DELAY: Duration = Duration::from_secs(2);

/// How the scanner is to scan, in the scanner's own units.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ScanConfig {
    /// Angular resolution in 1/100 degree: 25, 50 or 100.
    pub res: u16,
    /// Range resolution in mm: 1, 10 or 100.
    pub range_res: u32,
    /// Report the intensity bits.
    pub intensity: bool,
    /// First and last angle in 1/100 degree (−9000..=9000).
    pub min_angle: i32,
    /// Last angle in 1/100 degree.
    pub max_angle: i32,
}

impl ScanConfig {
    /// The scan width in degrees: 100 at 0.25°, else 180.
    pub fn width(&self) -> u16 {
        if self.res == 25 {
            100
        } else {
            180
        }
    }

    /// First and last scan segment (0-based), Player's `CheckScanConfig`.
    pub fn segments(&self) -> (u16, u16) {
        let half = i32::from(self.width()) * 50;
        let top = i32::from(self.width()) * 100 / i32::from(self.res);
        let seg = |a: i32| ((a + half) / i32::from(self.res)).clamp(0, top) as u16;
        (seg(self.min_angle), seg(self.max_angle))
    }

    /// Number of values per scan.
    pub fn count(&self) -> usize {
        let (a, b) = self.segments();
        usize::from(b.saturating_sub(a)) + 1
    }

    /// Maximum range in metres, as Player reports it.
    pub fn max_range(&self) -> f32 {
        match self.range_res {
            10 => 80.0,
            100 => 150.0,
            _ => 8.0,
        }
    }

    /// Checks the values the LMS200 can take.
    ///
    /// # Errors
    ///
    /// The first value it cannot take.
    pub fn check(&self) -> Result<(), ScanConfigError> {
        if ![25, 50, 100].contains(&self.res) {
            return Err(ScanConfigError::Resolution(self.res));
        }
        if ![1, 10, 100].contains(&self.range_res) {
            return Err(ScanConfigError::RangeResolution(self.range_res));
        }
        if self.min_angle > self.max_angle {
            return Err(ScanConfigError::Angles);
        }
        Ok(())
    }
}

/// A scan configuration the LMS200 cannot take.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ScanConfigError {
    /// Not 0.25, 0.5 or 1 degree.
    #[error("resolution {0} is not one of 25, 50, 100 (1/100 degree)")]
    Resolution(u16),
    /// Not 1, 10 or 100 mm.
    #[error("range_res {0} is not one of 1, 10, 100 (mm)")]
    RangeResolution(u32),
    /// The scan's ends the wrong way round.
    #[error("min_angle is greater than max_angle")]
    Angles,
}

/// How to reach the scanner.
#[derive(Debug, Clone)]
pub struct Settings {
    /// The serial device.
    pub port: PathBuf,
    /// Rates tried in order when connecting.
    pub connect_rates: Vec<u32>,
    /// The rate for data.
    pub transfer_rate: u32,
    /// Extra passes over `connect_rates` per connection attempt.
    pub retry: u32,
    /// Wait before the first connection (a scanner powered by the port).
    pub delay: Duration,
    /// High-availability mode.
    pub high_avail: bool,
    /// The scan.
    pub config: ScanConfig,
}

impl Settings {
    /// Player's connect rates and a 180° scan at `res` hundredths of a
    /// degree, in millimetres with intensity, streamed at `transfer` baud.
    pub fn scan_180(port: PathBuf, res: u16, transfer: u32) -> Settings {
        Settings {
            port,
            connect_rates: vec![9600, 38400, 500000],
            transfer_rate: transfer,
            retry: 0,
            delay: Duration::ZERO,
            high_avail: false,
            config: ScanConfig {
                res,
                range_res: 1,
                intensity: true,
                min_angle: -9000,
                max_angle: 9000,
            },
        }
    }
}

/// What the device thread tells the driver.
#[derive(Debug)]
pub enum Update {
    /// Connected, configured and streaming.
    Ready {
        /// The scanner's type string.
        kind: String,
        /// The line's rate.
        baud: u32,
    },
    /// A scan, with the configuration it was taken under.
    Scan(RawScan, ScanConfig),
    /// The session ended; the thread retries after [`RECONNECT_DELAY`].
    Lost(String),
    /// The answer to [`Order::Configure`].
    Configured(Result<ScanConfig, String>),
}

/// What the driver asks of the device thread.
#[derive(Debug)]
pub enum Order {
    /// Rescan with another configuration.
    Configure(ScanConfig),
    /// Stop streaming, put the scanner back to its connect rate, and end.
    Stop,
}

/// Counts kept across sessions.
#[derive(Debug, Default, Clone, Copy)]
struct Counts {
    sessions: u64,
    scans: u64,
    bad_scans: u64,
}

/// What can go wrong with the device itself; the line's failures and
/// stops are [`SessionError`]'s.
#[derive(Debug)]
enum Fail {
    NoReply(String),
    Refused(String),
    Silent(Duration),
}

impl std::fmt::Display for Fail {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Fail::NoReply(what) => write!(f, "no reply to {what}"),
            Fail::Refused(what) => write!(f, "the scanner refused {what}"),
            Fail::Silent(d) => write!(f, "no scan for {:.1} s", d.as_secs_f64()),
        }
    }
}

/// A session's end: the line's, or the device's [`Fail`].
type Error = SessionError<Fail>;

/// `Err` of the device's failure `f`.
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
        "sicklms200 line",
        move || waker.wake(),
        move |orders, reports, abort| run(settings, &reports, &orders, abort),
    )
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
        let first = counts.sessions == 1;
        let codec = TelegramCodec {
            addr: telegram::FROM_DEVICE,
        };
        let rate = settings.connect_rates[0];
        let port = settings.port.clone();
        let outcome = Link::session(&port, rate, codec, abort.clone(), |link| {
            Session {
                settings,
                link,
                orders,
                send: &send,
                counts: &mut counts,
            }
            .run(first)
        });
        // The scan counts go with the failure's log line.
        let _counts =
            tracing::warn_span!("laser", scans = counts.scans, bad_scans = counts.bad_scans)
                .entered();
        end_session(
            "laser",
            &port,
            counts.sessions,
            outcome,
            RECONNECT_DELAY,
            |why| {
                send(Update::Lost(why));
            },
        )
    };
    // A configuration that comes between sessions is taken up at the next.
    let between = |settings: &mut Settings, order| match order {
        Order::Stop => false,
        Order::Configure(c) => {
            settings.config = c;
            send(Update::Configured(Ok(c)));
            true
        }
    };
    run_sessions(&mut settings, orders, RECONNECT_DELAY, session, between);
}

struct Session<'a, F: Fn(Update)> {
    settings: &'a mut Settings,
    link: &'a mut Link<TelegramCodec>,
    orders: &'a Receiver<Order>,
    send: &'a F,
    counts: &'a mut Counts,
}

impl<F: Fn(Update)> Session<'_, F> {
    fn run(&mut self, first: bool) -> Result<(), Error> {
        let rates = self.settings.connect_rates.clone();
        if first && !self.settings.delay.is_zero() {
            tracing::info!(
                "waiting {} s for the laser to power up",
                self.settings.delay.as_secs()
            );
            std::thread::sleep(self.settings.delay);
        }
        let mut current = None;
        'connect: for _ in 0..=self.settings.retry {
            for &rate in &rates {
                self.link.port.set_baud(rate)?;
                tracing::debug!("trying {rate} baud");
                match self.mode(
                    mode::STOP,
                    &[],
                    "stop streaming",
                    Duration::from_millis(1000),
                ) {
                    Ok(()) => {
                        current = Some(rate);
                        break 'connect;
                    }
                    Err(SessionError::Device(Fail::NoReply(_))) => continue,
                    Err(e) => return Err(e),
                }
            }
        }
        let Some(mut baud) = current else {
            let list: Vec<String> = rates.iter().map(u32::to_string).collect();
            return fail(Fail::NoReply(format!(
                "stop streaming at {} baud (is the laser on and on this port?)",
                list.join(", ")
            )));
        };
        tracing::info!("laser answered at {baud} baud");
        let transfer = self.settings.transfer_rate;
        if baud != transfer {
            let m = telegram::baud_mode(transfer).ok_or_else(|| {
                SessionError::Device(Fail::Refused(format!(
                    "transfer rate {transfer} (not one the LMS200 has)"
                )))
            })?;
            self.mode(m, &[], "a baud rate change", Duration::from_secs(2))?;
            self.link.port.set_baud(transfer)?;
            baud = transfer;
            tracing::info!("laser switched to {baud} baud");
        }
        let kind = self.kind()?;
        let config = self.settings.config;
        self.configure(&kind, config)?;
        self.stream_start(config)?;
        tracing::info!("SICK laser type [{kind}] at {baud} baud: streaming");
        (self.send)(Update::Ready {
            kind: kind.clone(),
            baud,
        });
        self.stream(&kind)
    }

    /// Sends a request and waits for the reply `expect` (skipping scans
    /// still in flight), with Player's three tries.
    fn transact(
        &mut self,
        body: &[u8],
        expect: u8,
        what: &str,
        timeout: Duration,
    ) -> Result<Telegram, Error> {
        let bytes = telegram::request(body);
        for _ in 0..TRIES {
            self.link.flush();
            self.link.send(&bytes)?;
            let deadline = Instant::now() + timeout;
            loop {
                let left = deadline.saturating_duration_since(Instant::now());
                match self.link.read(left)? {
                    Some(t) if t.cmd() == expect => return Ok(t),
                    Some(t) if t.cmd() == cmd::NACK => return fail(Fail::Refused(what.into())),
                    Some(_) => continue,
                    None => break,
                }
            }
        }
        fail(Fail::NoReply(what.into()))
    }

    /// A mode change (0x20) and its 0xA0 reply, whose first data byte is 0 on success.
    fn mode(&mut self, m: u8, extra: &[u8], what: &str, timeout: Duration) -> Result<(), Error> {
        let mut body = vec![cmd::MODE, m];
        body.extend_from_slice(extra);
        let t = self.transact(&body, cmd::MODE | cmd::REPLY, what, timeout)?;
        match t.reply_data().first() {
            Some(0) => Ok(()),
            Some(1) => fail(Fail::Refused(format!("{what}: wrong password"))),
            _ => fail(Fail::Refused(what.into())),
        }
    }

    fn kind(&mut self) -> Result<String, Error> {
        let t = self.transact(
            &[cmd::TYPE],
            cmd::TYPE | cmd::REPLY,
            "the type request",
            Duration::from_secs(2),
        )?;
        let text: String = t
            .reply_data()
            .iter()
            .take_while(|&&b| b != 0)
            .map(|&b| char::from(b))
            .collect();
        Ok(text.trim().to_owned())
    }

    /// Configuration mode, variant and configuration, each written only
    /// when it differs from what the scanner has (it is flash memory).
    fn configure(&mut self, kind: &str, c: ScanConfig) -> Result<(), Error> {
        let mut password = b"SICK_".to_vec();
        password.extend(kind.bytes().chain(std::iter::repeat(b' ')).take(3));
        self.mode(
            mode::CONFIG,
            &password,
            "configuration mode",
            Duration::from_millis(2500),
        )?;

        let status = self.transact(
            &[cmd::STATUS],
            cmd::STATUS | cmd::REPLY,
            "the status request",
            Duration::from_secs(2),
        )?;
        let d = status.reply_data();
        let word = |i: usize| d.get(i..i + 2).map(|w| u16::from_le_bytes([w[0], w[1]]));
        if word(106) != Some(c.width()) || word(108) != Some(c.res) {
            tracing::info!("setting the scan to {}° at {}/100°", c.width(), c.res);
            let mut body = vec![cmd::VARIANT];
            body.extend_from_slice(&c.width().to_le_bytes());
            body.extend_from_slice(&c.res.to_le_bytes());
            let t = self.transact(
                &body,
                cmd::VARIANT | cmd::REPLY,
                "the variant",
                Duration::from_secs(2),
            )?;
            if t.reply_data().first() != Some(&1) {
                return fail(Fail::Refused(format!(
                    "the variant {}°/{}",
                    c.width(),
                    c.res
                )));
            }
        }

        let conf = self.transact(
            &[cmd::GET_CONFIG],
            cmd::GET_CONFIG | cmd::REPLY,
            "the configuration request",
            Duration::from_secs(2),
        )?;
        let mut data = conf.reply_data().to_vec();
        if data.len() < 7 {
            return fail(Fail::Refused(
                "the configuration request (short reply)".into(),
            ));
        }
        let want = [
            u8::from(self.settings.high_avail),
            u8::from(c.intensity),
            telegram::units_code(c.range_res),
        ];
        if data[4..7] != want {
            tracing::info!(
                "writing the configuration (units {} mm, intensity {})",
                c.range_res,
                c.intensity
            );
            data[4..7].copy_from_slice(&want);
            let mut body = vec![cmd::SET_CONFIG];
            body.extend_from_slice(&data);
            let t = self.transact(
                &body,
                cmd::SET_CONFIG | cmd::REPLY,
                "the configuration",
                Duration::from_secs(10),
            )?;
            if t.reply_data().first() != Some(&1) {
                return fail(Fail::Refused("the configuration".into()));
            }
        }
        Ok(())
    }

    fn stream_start(&mut self, c: ScanConfig) -> Result<(), Error> {
        let (a, b) = c.segments();
        let full = if c.res == 25 { 400 } else { 360 };
        if a == 0 && b == full {
            self.mode(
                mode::CONTINUOUS,
                &[],
                "continuous scans",
                Duration::from_secs(2),
            )
        } else {
            let mut extra = Vec::with_capacity(4);
            extra.extend_from_slice(&(a + 1).to_le_bytes());
            extra.extend_from_slice(&(b + 1).to_le_bytes());
            self.mode(
                mode::CONTINUOUS_PART,
                &extra,
                "continuous scans",
                Duration::from_secs(2),
            )
        }
    }

    fn stream(&mut self, kind: &str) -> Result<(), Error> {
        let mut config = self.settings.config;
        let mut patience = self.patience(config);
        let mut last = Instant::now();
        loop {
            match self.orders.try_recv() {
                Ok(Order::Stop) | Err(TryRecvError::Disconnected) => {
                    self.shut_down();
                    return Err(Error::Stopped);
                }
                Ok(Order::Configure(c)) => {
                    let result = self.configure(kind, c).and_then(|()| self.stream_start(c));
                    let reply = result.as_ref().map(|()| c).map_err(|e| e.to_string());
                    (self.send)(Update::Configured(reply));
                    result?;
                    self.settings.config = c;
                    config = c;
                    patience = self.patience(c);
                    last = Instant::now();
                }
                Err(TryRecvError::Empty) => {}
            }
            let read = match self.link.read(Duration::from_millis(100)) {
                Err(LinkError::Aborted) => {
                    self.shut_down();
                    return Err(Error::Stopped);
                }
                other => other?,
            };
            match read {
                Some(t) if t.cmd() == cmd::SCAN || t.cmd() == cmd::SCAN_PART => {
                    last = Instant::now();
                    match telegram::decode_scan(&t) {
                        Ok(raw) if raw.values.len() == config.count() => {
                            self.counts.scans += 1;
                            (self.send)(Update::Scan(raw, config));
                        }
                        Ok(raw) => {
                            self.counts.bad_scans += 1;
                            tracing::warn!(
                                bad_scans = self.counts.bad_scans,
                                "scan of {} values dropped: {} expected",
                                raw.values.len(),
                                config.count()
                            );
                        }
                        Err(e) => {
                            self.counts.bad_scans += 1;
                            tracing::warn!(bad_scans = self.counts.bad_scans, "scan dropped: {e}");
                        }
                    }
                }
                Some(t) => tracing::debug!("ignored telegram 0x{:02X}", t.cmd()),
                None if last.elapsed() > patience => return fail(Fail::Silent(last.elapsed())),
                None => {}
            }
        }
    }

    /// How long scans may pause before the scanner counts as lost: three
    /// telegrams' line time, and at least a second.
    fn patience(&self, c: ScanConfig) -> Duration {
        let bytes = 2 * c.count() + 16;
        let line = Duration::from_secs_f64(bytes as f64 * 10.0 / f64::from(self.link.port.baud()));
        (3 * line).max(Duration::from_secs(1))
    }

    /// Player's `MainQuit`: stop streaming and go back to the connect rate.
    fn shut_down(&mut self) {
        self.link.closing();
        let rate = self.settings.connect_rates[0];
        let quick = Duration::from_millis(300);
        if let Err(e) = self.mode(mode::STOP, &[], "stop streaming", quick) {
            tracing::warn!("cannot stop the laser's stream: {e}");
        }
        if self.link.port.baud() != rate {
            if let Some(m) = telegram::baud_mode(rate) {
                if let Err(e) = self.mode(m, &[], "a baud rate change", quick) {
                    tracing::warn!("cannot throttle the laser back to {rate} baud: {e}");
                }
            }
        }
        tracing::info!("laser stopped");
    }
}
