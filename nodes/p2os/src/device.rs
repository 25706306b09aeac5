//! The driver's side of the line: synchronises with the robot, opens it,
//! and streams SIPs, on a thread of its own.
//!
//! Player's `MainSetup`: at each baud rate in turn (9600, 38400, 19200,
//! 115200, 57600) send SYNC0 up to five times until the robot echoes it;
//! then SYNC1, then SYNC2, whose reply names the robot (name, class,
//! subclass). The first data byte of each reply drives the state, as in
//! Player; a robot still open from an earlier client (it answers with
//! SIPs) is sent CLOSE once and synchronised afresh. Then OPEN, PULSE, the
//! first SIP, and SONAR on when sonars are provided. Unlike Player, every
//! read has a deadline: a robot silent for a second ends the session, and
//! the driver reconnects.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::mpsc::{Receiver, TryRecvError};
use std::sync::Arc;
use std::time::{Duration, Instant};

use troupe_node::Waker;
use troupe_serial::{arcos, end_session, run_sessions, LineThread, Link, Reports, SessionError};

use crate::packet::{self, cmd, PacketCodec, Sip};
use crate::params::{self, Params};

/// Player's baud rates, in the order it tries them.
pub const BAUD_RATES: [u32; 5] = [9600, 38400, 19200, 115200, 57600];
/// How long to wait between two connection attempts.
pub const RECONNECT_DELAY: Duration = Duration::from_secs(2);
/// A robot that sends no SIP for this long is lost (it sends ten a second).
pub const SILENCE: Duration = Duration::from_secs(1);

/// How to drive the robot.
#[derive(Debug, Clone)]
pub struct Settings {
    /// The serial device.
    pub port: PathBuf,
    /// Turn the sonars on.
    pub sonar: bool,
    /// VEL2 wheel commands (Player's `direct_wheel_vel_control`) or VEL + RVEL.
    pub direct_wheel: bool,
    /// Speed limit, mm/s.
    pub max_speed: i32,
    /// Turn-rate limit, deg/s.
    pub max_turn: i32,
    /// Never drive the wheels in opposite directions (Player's `use_vel_band`).
    pub vel_band: bool,
    /// Send PULSE this often (Player's `pulse`).
    pub pulse: Option<Duration>,
    /// BUMP_STALL setting 0–3 (Player's `bumpstall`), if any.
    pub bumpstall: Option<u8>,
    /// Ask for gyro packets (a `gyro:::position2d` is provided).
    pub gyro: bool,
}

impl Settings {
    /// Player's defaults (sonars on, VEL2 wheel commands, 500 mm/s,
    /// 100°/s) for the robot at `port`.
    pub fn player_defaults(port: PathBuf) -> Settings {
        Settings {
            port,
            sonar: true,
            direct_wheel: true,
            max_speed: 500,
            max_turn: 100,
            vel_band: false,
            pulse: None,
            bumpstall: None,
            gyro: false,
        }
    }
}

/// What the line thread tells the driver.
#[derive(Debug)]
pub enum Update {
    /// Synchronised and open.
    Ready {
        /// Name, class and subclass from the SYNC2 reply.
        name: (String, String, String),
        /// The parameters chosen for the subclass.
        params: &'static Params,
        /// The line's rate.
        baud: u32,
    },
    /// A standard SIP.
    Sip(Sip),
    /// A gyro packet's mean rate (0–1023, 512 still).
    Gyro(u16),
    /// The session ended; the thread retries after [`RECONNECT_DELAY`].
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
    /// Odometry to zero (SETO).
    ResetOdom,
    /// VEL2 (true) or VEL + RVEL (false).
    DirectWheel(bool),
    /// GRIPPER with one of [`packet::grip`]'s arguments.
    Gripper(i32),
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
        "p2os line",
        move || waker.wake(),
        move |orders, reports, abort| run(settings, &reports, &orders, abort),
    )
}

/// What can go wrong with the device itself; the line's failures and
/// stops are [`SessionError`]'s.
#[derive(Debug)]
enum Fail {
    NoSync,
    NoReply(&'static str),
    Silent,
}

impl std::fmt::Display for Fail {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Fail::NoSync => write!(
                f,
                "no answer to SYNC0 at 9600, 38400, 19200, 115200 or 57600 baud (is the robot on and on this port?)"
            ),
            Fail::NoReply(what) => write!(f, "no reply to {what}"),
            Fail::Silent => write!(f, "no SIP for {} s", SILENCE.as_secs_f64()),
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
                params: &params::ROBOTS[0],
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
    params: &'static Params,
}

impl Session<'_> {
    fn send(&mut self, bytes: &[u8]) -> Result<(), Error> {
        self.link.send(bytes)?;
        Ok(())
    }

    /// The next packet within `timeout`, `None` if none came.
    fn read(&mut self, timeout: Duration) -> Result<Option<Vec<u8>>, Error> {
        Ok(self.link.read(timeout)?)
    }

    fn sync(&mut self) -> Result<(String, String, String), Error> {
        let mut closed_once = false;
        for &baud in &BAUD_RATES {
            self.link.port.set_baud(baud)?;
            self.link.flush();
            let mut step = cmd::SYNC0;
            let mut tries = 0;
            while tries < 5 {
                self.send(&packet::command(step))?;
                let reply = self.read(Duration::from_millis(400))?;
                let Some(data) = reply else {
                    if step == cmd::SYNC0 {
                        tries += 1;
                        continue;
                    }
                    return fail(Fail::NoReply(if step == cmd::SYNC1 {
                        "SYNC1"
                    } else {
                        "SYNC2"
                    }));
                };
                match data.first() {
                    Some(0) => step = cmd::SYNC1,
                    Some(1) => step = cmd::SYNC2,
                    Some(2) => {
                        tracing::info!("synchronised at {baud} baud");
                        return Ok(packet::parse_sync2(&data));
                    }
                    _ if !closed_once => {
                        // A robot still open from an earlier client.
                        tracing::info!("robot already open: closing it first");
                        closed_once = true;
                        self.send(&packet::command(cmd::CLOSE))?;
                        std::thread::sleep(Duration::from_millis(400));
                        self.link.flush();
                        step = cmd::SYNC0;
                    }
                    _ => tries += 1,
                }
            }
        }
        fail(Fail::NoSync)
    }

    fn run(&mut self, send: &impl Fn(Update)) -> Result<(), Error> {
        let (name, class, subclass) = self.sync()?;
        self.params = match params::find(&subclass) {
            Some(p) => p,
            None => {
                tracing::warn!(
                    "unknown robot subclass `{subclass}`: using {}'s parameters, as Player does",
                    params::ROBOTS[0].subclass
                );
                &params::ROBOTS[0]
            }
        };
        tracing::info!("connected to {name}, a {class} {subclass}");
        self.send(&packet::command(cmd::OPEN))?;
        self.send(&packet::command(cmd::PULSE))?;
        let first = loop {
            match self.read(SILENCE)? {
                Some(d) if Sip::is_standard(&d) => break d,
                Some(_) => continue,
                None => return fail(Fail::NoReply("OPEN (no SIP)")),
            }
        };
        self.send(&packet::command_int(
            cmd::SONAR,
            i32::from(self.settings.sonar),
        ))?;
        if let Some(b) = self.settings.bumpstall {
            self.send(&packet::command_int(cmd::BUMP_STALL, i32::from(b)))?;
        }
        if self.settings.gyro {
            self.send(&packet::command_int(cmd::GYRO, 1))?;
        }
        let baud = self.link.port.baud();
        send(Update::Ready {
            name: (name, class, subclass),
            params: self.params,
            baud,
        });
        self.forward(&first, send);
        self.stream(send)
    }

    fn forward(&mut self, data: &[u8], send: &impl Fn(Update)) {
        match Sip::decode(data) {
            Ok(sip) => send(Update::Sip(sip)),
            Err(e) => tracing::warn!("SIP dropped: {e}"),
        }
    }

    fn stream(&mut self, send: &impl Fn(Update)) -> Result<(), Error> {
        let mut last_sip = Instant::now();
        let mut last_pulse = Instant::now();
        loop {
            loop {
                match self.orders.try_recv() {
                    Ok(Order::Stop) | Err(TryRecvError::Disconnected) => {
                        self.goodbye();
                        return Err(Error::Stopped);
                    }
                    Ok(o) => {
                        self.obey(o)?;
                        last_pulse = Instant::now();
                    }
                    Err(TryRecvError::Empty) => break,
                }
            }
            if let Some(p) = self.settings.pulse {
                if last_pulse.elapsed() >= p {
                    self.send(&packet::command(cmd::PULSE))?;
                    last_pulse = Instant::now();
                }
            }
            let packet = match self.read(Duration::from_millis(50)) {
                Err(Error::Stopped) => {
                    self.goodbye();
                    return Err(Error::Stopped);
                }
                other => other?,
            };
            match packet {
                Some(d) if Sip::is_standard(&d) => {
                    last_sip = Instant::now();
                    self.forward(&d, send);
                }
                Some(d) if d.first() == Some(&packet::GYROPAC) => match packet::parse_gyro(&d) {
                    Ok(rate) => send(Update::Gyro(rate)),
                    Err(e) => tracing::warn!("gyro packet dropped: {e}"),
                },
                Some(d) => tracing::debug!(
                    "ignored packet type 0x{:02X}",
                    d.first().copied().unwrap_or(0)
                ),
                None if last_sip.elapsed() > SILENCE => return fail(Fail::Silent),
                None => {}
            }
        }
    }

    /// Player's `MainQuit`.
    fn goodbye(&mut self) {
        arcos::stop_and_close(&mut self.link.port);
    }

    fn obey(&mut self, o: Order) -> Result<(), Error> {
        match o {
            Order::Enable(on) => self.send(&packet::command_int(cmd::ENABLE, i32::from(on))),
            Order::ResetOdom => self.send(&packet::frame(&[cmd::SETO, packet::ARGINT])),
            Order::DirectWheel(d) => {
                self.settings.direct_wheel = d;
                Ok(())
            }
            Order::Vel { speed, turn } => {
                let bytes = velocity(self.settings, self.params, speed, turn);
                for b in bytes {
                    self.send(&b)?;
                }
                Ok(())
            }
            Order::Gripper(arg) => self.send(&packet::command_int(cmd::GRIPPER, arg)),
            Order::Stop => Ok(()),
        }
    }
}

/// The packets for a velocity command (Player's `HandlePositionCommand`).
pub fn velocity(s: &Settings, p: &Params, speed: i32, turn: i32) -> Vec<Vec<u8>> {
    if !s.direct_wheel {
        let v = speed.clamp(-s.max_speed, s.max_speed);
        let w = turn.clamp(-s.max_turn, s.max_turn);
        return vec![
            packet::command_int(cmd::VEL, v),
            packet::command_int(cmd::RVEL, w),
        ];
    }
    let (left, right) = arcos::wheels(
        f64::from(speed),
        f64::from(turn),
        p.diff_conv,
        f64::from(s.max_speed),
        s.vel_band,
    );
    let unit = |v: f64| (v / p.vel2_div).trunc() as i32;
    vec![packet::vel2(unit(right), unit(left))]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn settings() -> Settings {
        Settings::player_defaults(PathBuf::new())
    }

    /// Player's worked example: p3dx-sh, 0.3 m/s and 0.5 rad/s (29°/s).
    #[test]
    fn velocity_becomes_vel2_or_vel_and_rvel() {
        let p = params::find("p3dx-sh").unwrap();
        let s = settings();
        assert_eq!(velocity(&s, p, 300, 29), vec![packet::vel2(19, 10)]);
        // Clamped to the speed limit, keeping the ratio.
        let fast = velocity(&s, p, 2000, 0);
        assert_eq!(fast, vec![packet::vel2(25, 25)]);
        let s = Settings {
            direct_wheel: false,
            ..settings()
        };
        assert_eq!(
            velocity(&s, p, -200, -300),
            vec![
                packet::command_int(cmd::VEL, -200),
                packet::command_int(cmd::RVEL, -100)
            ]
        );
    }
}
