//! The driver's side of the Erratic's line, on a thread of its own.
//!
//! Player's `Connect`, with its baud-rate table fixed: at 38400 and then
//! 115200 baud, ask for the configuration packet (every 250 ms, twelve
//! times) until the robot answers with its name, type and revision; then
//! OPEN, PULSE, and the settings from the cfg (accelerations, PID gains,
//! PWM, a save), each written only when set. Sonar and analog inputs are
//! turned on when their devices are provided. Motor packets must keep
//! coming (ten a second); a robot silent for a second is lost, and the
//! driver reconnects every 2 s. A PULSE goes out whenever nothing else has
//! for a second, so the robot's watchdog keeps quiet.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::mpsc::{Receiver, TryRecvError};
use std::sync::Arc;
use std::time::{Duration, Instant};

use troupe_node::Waker;
use troupe_serial::{arcos, end_session, run_sessions, LineThread, Link, Reports, SessionError};

use crate::packet::{self, cmd, kind, PacketCodec};
use crate::params::{self, Params};

/// The rates tried, in order.
pub const BAUD_RATES: [u32; 2] = [38400, 115200];
/// Between two connection attempts.
pub const RECONNECT_DELAY: Duration = Duration::from_secs(2);
/// A robot without a motor packet for this long is lost.
pub const SILENCE: Duration = Duration::from_secs(1);
/// A PULSE goes out when nothing else has for this long.
pub const PULSE: Duration = Duration::from_secs(1);

/// How to drive the robot.
#[derive(Debug, Clone)]
pub struct Settings {
    /// The serial device.
    pub port: PathBuf,
    /// VEL2 wheel commands or VEL + RVEL.
    pub direct_wheel: bool,
    /// Speed limit, mm/s.
    pub max_speed: i32,
    /// Turn-rate limit, deg/s.
    pub max_turn: i32,
    /// Turn the sonars on.
    pub sonar: bool,
    /// Turn the analog inputs (IR) on.
    pub analog: bool,
    /// Settings written after OPEN, already framed, in Player's order.
    pub startup: Vec<Vec<u8>>,
}

/// What the line thread tells the driver.
#[derive(Debug)]
pub enum Update {
    /// Connected and open.
    Ready {
        /// Name, type, subtype from the configuration reply.
        name: (String, String, String),
        /// The revision's parameters.
        params: &'static Params,
        /// The line's rate.
        baud: u32,
    },
    /// A packet from the robot (type first).
    Packet(Vec<u8>),
    /// The session ended.
    Lost(String),
}

/// What the driver asks of the line thread.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Order {
    /// Velocity: mm/s and deg/s.
    Vel {
        /// Forward speed, mm/s.
        speed: i32,
        /// Turn rate, deg/s.
        turn: i32,
    },
    /// Motors on or off.
    Enable(bool),
    /// VEL2 (true) or VEL + RVEL.
    DirectWheel(bool),
    /// A servo to an angle in radians.
    Servo(u8, f64),
    /// STOP, CLOSE and end.
    Stop,
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
        "erratic line",
        move || waker.wake(),
        move |orders, reports, abort| run(settings, &reports, &orders, abort),
    )
}

/// What can go wrong with the device itself; the line's failures and
/// stops are [`SessionError`]'s.
#[derive(Debug)]
enum Fail {
    NoConfig,
    Silent,
}

impl std::fmt::Display for Fail {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Fail::NoConfig => f.write_str(
                "no configuration reply at 38400 or 115200 baud (is the robot on and on this port?)",
            ),
            Fail::Silent => write!(f, "no motor packet for {} s", SILENCE.as_secs_f64()),
        }
    }
}

/// A session's end: the line's, or the device's [`Fail`].
type Error = SessionError<Fail>;

/// `Err` of the device's failure `f`.
fn fail<T>(f: Fail) -> Result<T, Error> {
    Err(SessionError::Device(f))
}

fn run(
    mut settings: Settings,
    reports: &Reports<Update>,
    orders: &Receiver<Order>,
    abort: Arc<AtomicBool>,
) {
    let send = |u: Update| reports.send(u);
    let mut sessions = 0u64;
    let session = |settings: &mut Settings| {
        sessions += 1;
        let port = settings.port.clone();
        let outcome = Link::session(&port, BAUD_RATES[0], PacketCodec, abort.clone(), |link| {
            Session {
                settings,
                link,
                orders,
                last_sent: Instant::now(),
            }
            .run(&send)
        });
        end_session("robot", &port, sessions, outcome, RECONNECT_DELAY, |why| {
            send(Update::Lost(why));
        })
    };
    let between = |settings: &mut Settings, order| match order {
        Order::Stop => false,
        Order::DirectWheel(d) => {
            settings.direct_wheel = d;
            true
        }
        _ => true,
    };
    run_sessions(&mut settings, orders, RECONNECT_DELAY, session, between);
}

struct Session<'a> {
    settings: &'a mut Settings,
    link: &'a mut Link<PacketCodec>,
    orders: &'a Receiver<Order>,
    last_sent: Instant,
}

impl Session<'_> {
    fn send(&mut self, bytes: &[u8]) -> Result<(), Error> {
        self.link.send(bytes)?;
        self.last_sent = Instant::now();
        Ok(())
    }

    fn read(&mut self, timeout: Duration) -> Result<Option<Vec<u8>>, Error> {
        Ok(self.link.read(timeout)?)
    }

    fn connect(&mut self) -> Result<(String, String, String), Error> {
        for &baud in &BAUD_RATES {
            self.link.port.set_baud(baud)?;
            self.link.flush();
            for _ in 0..12 {
                self.send(&packet::command(cmd::CONFIG))?;
                let deadline = Instant::now() + Duration::from_millis(250);
                while let Some(p) = self.read(deadline.saturating_duration_since(Instant::now()))? {
                    if p.first() == Some(&kind::CONFIG) {
                        tracing::info!("configuration reply at {baud} baud");
                        return Ok(packet::parse_config(&p));
                    }
                }
            }
        }
        fail(Fail::NoConfig)
    }

    fn run(&mut self, send: &impl Fn(Update)) -> Result<(), Error> {
        let name = self.connect()?;
        let params = params::find(&name.2).unwrap_or_else(|| {
            tracing::warn!(
                "unknown Erratic revision `{}`: using Rev E's parameters, as Player does",
                name.2
            );
            &params::REVISIONS[0]
        });
        tracing::info!("connected to {}, a {} {}", name.0, name.1, name.2);
        self.send(&packet::command(cmd::OPEN))?;
        self.send(&packet::command(cmd::PULSE))?;
        for p in self.settings.startup.clone() {
            self.send(&p)?;
        }
        self.send(&packet::command_int(
            cmd::SONAR,
            i32::from(self.settings.sonar),
        ))?;
        self.send(&packet::command_int(
            cmd::ANALOG,
            i32::from(self.settings.analog),
        ))?;
        let baud = self.link.port.baud();
        send(Update::Ready { name, params, baud });
        self.stream(send)
    }

    fn stream(&mut self, send: &impl Fn(Update)) -> Result<(), Error> {
        let mut last_motor = Instant::now();
        loop {
            // The latest velocity wins: Player's 50 ms throttle dropped
            // commands (a final stop could be lost); this keeps the newest.
            let mut vel = None;
            loop {
                match self.orders.try_recv() {
                    Ok(Order::Stop) | Err(TryRecvError::Disconnected) => {
                        self.goodbye();
                        return Err(Error::Stopped);
                    }
                    Ok(Order::Vel { speed, turn }) => vel = Some((speed, turn)),
                    Ok(o) => self.obey(o)?,
                    Err(TryRecvError::Empty) => break,
                }
            }
            if let Some((speed, turn)) = vel {
                for p in velocity(self.settings, speed, turn) {
                    self.send(&p)?;
                }
            }
            if self.last_sent.elapsed() >= PULSE {
                self.send(&packet::command(cmd::PULSE))?;
            }
            let packet = match self.read(Duration::from_millis(50)) {
                Err(Error::Stopped) => {
                    self.goodbye();
                    return Err(Error::Stopped);
                }
                other => other?,
            };
            match packet {
                Some(p) if p.first().is_some_and(|k| kind::MOTOR.contains(k)) => {
                    last_motor = Instant::now();
                    send(Update::Packet(p));
                }
                Some(p) if matches!(p.first(), Some(&kind::SONAR | &kind::ANALOG)) => {
                    send(Update::Packet(p))
                }
                Some(p) => tracing::debug!(
                    "ignored packet type 0x{:02X}",
                    p.first().copied().unwrap_or(0)
                ),
                None if last_motor.elapsed() > SILENCE => return fail(Fail::Silent),
                None => {}
            }
        }
    }

    fn obey(&mut self, o: Order) -> Result<(), Error> {
        match o {
            Order::Enable(on) => self.send(&packet::command_int(cmd::ENABLE, i32::from(on))),
            Order::DirectWheel(d) => {
                self.settings.direct_wheel = d;
                Ok(())
            }
            Order::Servo(n, a) => self.send(&packet::servo(n, a)),
            Order::Vel { .. } | Order::Stop => Ok(()),
        }
    }

    /// Servo commands already queued still go out (a pan-tilt command just
    /// before shutdown is not lost); velocities do not, the stop follows.
    fn goodbye(&mut self) {
        while let Ok(o) = self.orders.try_recv() {
            if let Order::Servo(n, a) = o {
                if self.send(&packet::servo(n, a)).is_err() {
                    break;
                }
            }
        }
        arcos::stop_and_close(&mut self.link.port);
    }
}

/// The packets for a velocity command (Player's `HandlePositionCommand`,
/// with the other wheel scaled when one is limited).
pub fn velocity(s: &Settings, speed: i32, turn: i32) -> Vec<Vec<u8>> {
    if !s.direct_wheel {
        return vec![
            packet::command_int(cmd::VEL, speed.clamp(-s.max_speed, s.max_speed)),
            packet::command_int(cmd::RVEL, turn.clamp(-s.max_turn, s.max_turn)),
        ];
    }
    let (l, r) = arcos::wheels(
        f64::from(speed),
        f64::from(turn),
        params::DIFF_CONV,
        f64::from(s.max_speed),
        false,
    );
    let unit = |v: f64| (v / params::VEL2_DIV).trunc() as i32;
    vec![packet::vel2(unit(r), unit(l))]
}
