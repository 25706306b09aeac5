//! The driver's side of the M3 board's line, on a thread of its own.
//!
//! Player's `MainSetup`: the line at 416666 baud, 8N2; both chips reset
//! and asked their version (a board that does not answer is not there);
//! the cycle time read; microsteps, output mode, zeroed positions, the
//! acceleration profile; motors off. Then, every 100 ms, the chips are
//! polled for what the cfg provides (wheel positions and velocities, the
//! eight IR inputs, the eight analog inputs, the digital inputs) and the
//! poll goes to the driver as one [`Sample`]. Orders are carried out
//! between polls. A board silent for a second is lost; the driver
//! reconnects every 2 s. On stop, Player's `StopRobot`: the wheels
//! stopped abruptly, the motors unpowered, the chips reset.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::sync::Arc;
use std::time::{Duration, Instant};

use troupe_geom::Pose;
use troupe_node::Waker;
use troupe_serial::{end_session, run_sessions, LineThread, Link, Reports, SessionError, StopBits};

use crate::pmd::{self, op, ReplyCodec, LEFT, RIGHT};
use crate::robot::{self, Odometry};

/// Between two connection attempts.
pub const RECONNECT_DELAY: Duration = Duration::from_secs(2);
/// How long a chip has to answer.
pub const REPLY_TIMEOUT: Duration = Duration::from_millis(100);
/// A board that has answered nothing for this long is lost.
pub const SILENCE: Duration = Duration::from_secs(1);
/// Between two polls.
pub const CYCLE: Duration = Duration::from_millis(100);

/// What to poll and how to drive.
#[derive(Debug, Clone)]
pub struct Settings {
    /// The serial device.
    pub port: PathBuf,
    /// Motor torque when enabled, percent (20–100).
    pub torque: i64,
    /// Poll the wheels (position2d is provided).
    pub position: bool,
    /// Poll the IR inputs.
    pub ir: bool,
    /// Poll the analog inputs.
    pub aio: bool,
    /// Poll the digital inputs.
    pub dio: bool,
    /// Log every command and reply.
    pub debug: bool,
}

/// The wheels' part of a poll.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Motion {
    /// Dead-reckoned pose.
    pub pose: Pose,
    /// Forward speed, m/s.
    pub speed: f64,
    /// Turn rate, rad/s.
    pub turn: f64,
}

/// One poll of the board; `None` for what is not polled or did not answer.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Sample {
    /// Odometry and velocities.
    pub motion: Option<Motion>,
    /// The IR inputs, ADC counts.
    pub ir: Option<[u16; 8]>,
    /// The analog inputs, ADC counts.
    pub aio: Option<[u16; 8]>,
    /// The 16 digital inputs, as the board gives them.
    pub dio: Option<u16>,
}

/// What the line thread tells the driver.
#[derive(Debug)]
pub enum Update {
    /// Connected and set up.
    Ready {
        /// The chips' versions, left then right.
        versions: (i32, i32),
        /// Their cycle, µs.
        cycle_us: i32,
    },
    /// A poll.
    Sample(Sample),
    /// The session ended.
    Lost(String),
}

/// What the driver asks of the line thread.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Order {
    /// Forward speed (m/s) and turn rate (rad/s).
    Vel(f64, f64),
    /// Motor power on or off.
    Enable(bool),
    /// Odometry to zero (the chips' positions too).
    ResetOdom,
    /// Odometry to this pose.
    SetOdom(Pose),
    /// Digital outputs: how many, and their bits.
    Dio(u32, u32),
    /// Stop the robot and end.
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
        "wbr914 line",
        move || waker.wake(),
        move |orders, reports, abort| run(settings, &reports, &orders, abort),
    )
}

/// What can go wrong with the board itself.
#[derive(Debug)]
enum Fail {
    NoVersion,
    Silent,
}

impl std::fmt::Display for Fail {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Fail::NoVersion => write!(
                f,
                "the motion chips did not answer GETVERSION at {} baud (is the 914's M3 board on, and on this port?)",
                pmd::BAUD
            ),
            Fail::Silent => write!(f, "no reply from the board for {} s", SILENCE.as_secs_f64()),
        }
    }
}

type Error = SessionError<Fail>;

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
        let outcome = Link::session(
            &port,
            pmd::BAUD,
            ReplyCodec::default(),
            abort.clone(),
            |link| {
                let mut s = Session {
                    settings,
                    link,
                    orders,
                    k: robot::velocity_k(robot::DEFAULT_CYCLE_US),
                    enabled: false,
                    odometry: Odometry::default(),
                    digital_out: 0,
                    last_reply: Instant::now(),
                    missed: 0,
                };
                let result = s.run(&send);
                if s.missed > 0 {
                    tracing::warn!(
                        missed = s.missed,
                        "{} commands of the session got no good reply",
                        s.missed
                    );
                }
                result
            },
        );
        end_session("robot", &port, sessions, outcome, RECONNECT_DELAY, |why| {
            send(Update::Lost(why));
        })
    };
    run_sessions(&mut settings, orders, RECONNECT_DELAY, session, |_, o| {
        o != Order::Stop
    });
}

struct Session<'a> {
    settings: &'a Settings,
    link: &'a mut Link<ReplyCodec>,
    orders: &'a Receiver<Order>,
    /// Velocity units per m/s.
    k: f64,
    enabled: bool,
    odometry: Odometry,
    digital_out: u16,
    last_reply: Instant,
    missed: u64,
}

impl Session<'_> {
    /// Sends one command and reads its reply: the value, or `None` when
    /// the chip refused or did not answer (logged, counted).
    fn ask(&mut self, axis: u8, opcode: u8, arg: i32) -> Result<Option<i32>, Error> {
        self.link.flush();
        self.link.framer.codec_mut().expect(opcode);
        self.link.send(&pmd::command(axis, opcode, arg))?;
        let got = self.link.read(REPLY_TIMEOUT)?;
        if self.settings.debug {
            tracing::info!("chip {axis}: 0x{opcode:02X} {arg} -> {got:?}");
        }
        let why = match got {
            Some(Ok(v)) => {
                self.last_reply = Instant::now();
                return Ok(Some(v));
            }
            Some(Err(status)) => {
                self.last_reply = Instant::now();
                format!(
                    "chip {axis} refused command 0x{opcode:02X}: {}",
                    pmd::status_text(status)
                )
            }
            None => format!("no reply from chip {axis} to command 0x{opcode:02X}"),
        };
        self.missed += 1;
        if self.missed == 1 {
            tracing::warn!("{why} (further misses are counted)");
        } else {
            tracing::debug!("{why}");
        }
        if self.last_reply.elapsed() > SILENCE {
            return Err(SessionError::Device(Fail::Silent));
        }
        Ok(None)
    }

    /// The same command to both chips, left first, as Player sends them.
    fn both(&mut self, opcode: u8, arg: i32) -> Result<(), Error> {
        self.ask(LEFT, opcode, arg)?;
        self.ask(RIGHT, opcode, arg)?;
        Ok(())
    }

    fn run(&mut self, send: &impl Fn(Update)) -> Result<(), Error> {
        self.link.port.set_stop_bits(StopBits::Two)?;
        self.both(op::RESET, 0)?;
        let left = self.ask(LEFT, op::GETVERSION, 0)?;
        let right = self.ask(RIGHT, op::GETVERSION, 0)?;
        let (Some(vl), Some(vr)) = (left, right) else {
            return Err(SessionError::Device(Fail::NoVersion));
        };
        let cycle_us = match self.ask(LEFT, op::GETSAMPLETIME, 0)? {
            Some(c) if c > 0 => c,
            other => {
                tracing::warn!(
                    "cycle time {other:?}: using {} µs, Player's default",
                    robot::DEFAULT_CYCLE_US
                );
                robot::DEFAULT_CYCLE_US
            }
        };
        self.k = robot::velocity_k(cycle_us);
        self.both(op::SETPHASECOUNTS, robot::PHASE_COUNTS)?;
        // PWM sign-magnitude output.
        self.both(op::SETOUTPUTMODE, 1)?;
        self.reset_positions()?;
        self.both(op::SETACCEL, robot::ACCELERATION)?;
        self.both(op::SETDECEL, robot::DECELERATION)?;
        self.both(op::SETPROFILEMODE, pmd::TRAPEZOIDAL)?;
        self.both(op::UPDATE, 0)?;
        self.enable(false)?;
        send(Update::Ready {
            versions: (vl, vr),
            cycle_us,
        });
        let ended = self.stream(send);
        // However the stop came (an order, or the abort flag mid-poll).
        if let Err(SessionError::Stopped) = ended {
            self.goodbye();
        }
        ended
    }

    fn stream(&mut self, send: &impl Fn(Update)) -> Result<(), Error> {
        let mut next = Instant::now();
        loop {
            let wait = next.saturating_duration_since(Instant::now());
            let first = match self.orders.recv_timeout(wait) {
                Ok(o) => Some(o),
                Err(RecvTimeoutError::Timeout) => None,
                Err(RecvTimeoutError::Disconnected) => Some(Order::Stop),
            };
            // The latest velocity wins; the other orders are carried out in turn.
            let mut vel = None;
            for o in first.into_iter().chain(self.orders.try_iter()) {
                match o {
                    Order::Vel(v, w) => vel = Some((v, w)),
                    o => self.obey(o)?,
                }
            }
            if let Some((v, w)) = vel {
                self.velocity(v, w)?;
            }
            let now = Instant::now();
            if now >= next {
                let sample = self.poll()?;
                send(Update::Sample(sample));
                next += CYCLE;
                if next < now {
                    next = now + CYCLE;
                }
            }
        }
    }

    fn obey(&mut self, o: Order) -> Result<(), Error> {
        match o {
            Order::Stop => Err(SessionError::Stopped),
            Order::Vel(v, w) => self.velocity(v, w),
            Order::Enable(on) => self.enable(on),
            Order::ResetOdom => self.reset_positions(),
            Order::SetOdom(pose) => {
                // Player also wrote x and y into the left chip's position
                // (both into one chip, and the wheels' counts lost): here the
                // counts stay and the pose is what the client said.
                self.odometry.pose = pose;
                Ok(())
            }
            Order::Dio(count, bits) => {
                let out = robot::digital_out(self.digital_out, count, bits);
                self.digital_out = out;
                self.ask(RIGHT, op::WRITEDIGITAL, i32::from(out.swap_bytes()))?;
                Ok(())
            }
        }
    }

    /// The chips' positions and the odometry to zero.
    fn reset_positions(&mut self) -> Result<(), Error> {
        self.both(op::SETACTUALPOS, 0)?;
        self.both(op::UPDATE, 0)?;
        self.odometry.reset();
        Ok(())
    }

    /// Player's `EnableMotors`: torque off, then on at the cfg's torque
    /// with the motors' mode on.
    fn enable(&mut self, on: bool) -> Result<(), Error> {
        let torque = if on {
            (self.settings.torque * 0x8000 / 100).min(0x7FFF) as i32
        } else {
            0
        };
        self.both(op::SETMOTORMODE, 0)?;
        self.both(op::SETMOTORCMD, torque)?;
        self.both(op::UPDATE, 0)?;
        if on {
            self.both(op::SETMOTORMODE, 1)?;
        }
        self.enabled = on;
        Ok(())
    }

    /// Player's `HandleVelocityCommand`: the wheels' speeds in velocity
    /// contouring mode, zero while the motors are off.
    fn velocity(&mut self, speed: f64, turn: f64) -> Result<(), Error> {
        let (l, r) = robot::wheels(speed, turn);
        let units = |mps: f64| (mps * self.k) as i32;
        let (lv, rv) = if self.enabled {
            (units(l), units(r))
        } else {
            if speed != 0.0 || turn != 0.0 {
                tracing::warn!("motors off: a client enables them (position2d motor power) before the robot moves");
            }
            (0, 0)
        };
        self.both(op::SETPROFILEMODE, pmd::VELOCITY_CONTOURING)?;
        self.ask(LEFT, op::SETVEL, -lv)?;
        self.ask(RIGHT, op::SETVEL, rv)?;
        self.both(op::UPDATE, 0)
    }

    fn poll(&mut self) -> Result<Sample, Error> {
        let mut s = Sample::default();
        if self.settings.position {
            let l = self.ask(LEFT, op::GETCMDPOS, 0)?;
            let r = self.ask(RIGHT, op::GETCMDPOS, 0)?;
            let lv = self.ask(LEFT, op::GETCMDVEL, 0)?;
            let rv = self.ask(RIGHT, op::GETCMDVEL, 0)?;
            if let (Some(l), Some(r), Some(lv), Some(rv)) = (l, r, lv, rv) {
                let pose = self.odometry.update(l.wrapping_neg(), r);
                let (speed, turn) = robot::motion(-f64::from(lv) / self.k, f64::from(rv) / self.k);
                s.motion = Some(Motion { pose, speed, turn });
            }
        }
        if self.settings.ir {
            s.ir = self.analog(LEFT)?;
        }
        if self.settings.aio {
            s.aio = self.analog(RIGHT)?;
        }
        if self.settings.dio {
            s.dio = self.ask(RIGHT, op::READDIGITAL, 0)?.map(|v| v as u16);
        }
        Ok(s)
    }

    /// The eight analog inputs of chip `axis` (the IR sensors are on the
    /// left chip, the second I/O board's inputs on the right).
    fn analog(&mut self, axis: u8) -> Result<Option<[u16; 8]>, Error> {
        let mut out = [0; 8];
        for (c, slot) in (0..).zip(out.iter_mut()) {
            match self.ask(axis, op::READANALOG, c)? {
                Some(v) => *slot = robot::analog(v),
                None => return Ok(None),
            }
        }
        Ok(Some(out))
    }

    /// Player's `StopRobot` and `EnableMotors(false)`, replies or not.
    fn goodbye(&mut self) {
        self.link.closing();
        let mut steps = Vec::new();
        for axis in [LEFT, RIGHT] {
            steps.extend([
                (axis, op::RESETEVENTSTATUS, 0),
                (axis, op::SETSTOPMODE, 1),
                (axis, op::SETVEL, 0),
                (axis, op::SETACCEL, 0),
                (axis, op::SETDECEL, 0),
            ]);
        }
        let ok = steps
            .into_iter()
            .try_for_each(|(axis, opcode, arg)| self.ask(axis, opcode, arg).map(drop))
            .and_then(|()| self.both(op::SETPROFILEMODE, pmd::VELOCITY_CONTOURING))
            .and_then(|()| self.enable(false))
            .and_then(|()| self.both(op::RESET, 0));
        match ok {
            Ok(()) => tracing::info!("robot stopped, motors off"),
            Err(e) => tracing::warn!("stopping the robot: {e}"),
        }
    }
}
