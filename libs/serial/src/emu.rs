//! The device end of an emulated serial line.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use rand::rngs::StdRng;
use rand::SeedableRng;

use crate::capture::Recorder;
use crate::faults::{Faults, Injected};
use crate::pty::{Pacer, Pty};
use crate::{Codec, Framer};

/// What [`EmuLine::recv`] saw.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LineEvent {
    /// This many bytes arrived at the device's baud rate.
    Received(usize),
    /// Nothing (or only bytes at the wrong rate) arrived in time.
    Idle,
    /// The device was unplugged (by the fault plan); nothing goes through.
    Unplugged,
    /// The device was plugged back in: it powers up afresh.
    Replugged,
}

/// How an emulated line is set up: shared by every device emulator.
#[derive(Debug, Clone)]
pub struct LineOptions {
    /// The path to link the pseudo-terminal at.
    pub link: PathBuf,
    /// Faults to inject on what the device sends.
    pub faults: Faults,
    /// Seed of the fault generator (runs with the same seed fail alike).
    pub seed: u64,
    /// Write what crosses the line, both ways, to this capture file.
    pub capture: Option<PathBuf>,
}

/// A pseudo-terminal linked at a path, seen from the device: bytes sent at
/// another baud rate than the device's are garbage to it, what it sends
/// takes real line time, and [`Faults`] are applied on the way out.
#[derive(Debug)]
pub struct EmuLine {
    link: PathBuf,
    pty: Option<Pty>,
    pacer: Pacer,
    faults: Faults,
    rng: StdRng,
    plugged_at: Instant,
    unplugged_at: Option<Instant>,
    /// When the device last understood something from the driver.
    last_heard: Instant,
    barked: bool,
    /// Faults injected so far.
    pub injected: Injected,
    /// Bytes received at a baud rate other than the device's.
    pub wrong_baud: u64,
    /// Where what crosses the line (what the device understood, and what
    /// it sent after the faults) is written, if anywhere.
    recorder: Option<Recorder>,
}

impl EmuLine {
    /// Opens a pseudo-terminal for `device` (a name for the capture) and
    /// links it at `opts.link`, recording to `opts.capture` if given.
    ///
    /// # Errors
    ///
    /// When no pseudo-terminal can be had, the link cannot be made, or the
    /// capture file cannot be created.
    pub fn open(opts: &LineOptions, device: &str) -> std::io::Result<EmuLine> {
        let link = opts.link.as_path();
        let recorder = opts
            .capture
            .as_deref()
            .map(|path| Recorder::create(path, &format!("an emulated {device}")))
            .transpose()?;
        let mut pty = Pty::open()?;
        pty.link(link)?;
        tracing::info!(
            "emulated device at {} -> {}",
            link.display(),
            pty.slave_path().display()
        );
        Ok(EmuLine {
            link: link.to_owned(),
            pty: Some(pty),
            pacer: Pacer::new(),
            faults: opts.faults.clone(),
            rng: StdRng::seed_from_u64(opts.seed),
            plugged_at: Instant::now(),
            unplugged_at: None,
            last_heard: Instant::now(),
            barked: false,
            injected: Injected::default(),
            wrong_baud: 0,
            recorder,
        })
    }

    /// The link path.
    pub fn link(&self) -> &Path {
        &self.link
    }

    /// The faults in force.
    pub fn faults(&self) -> &Faults {
        &self.faults
    }

    /// Once the emulator is told to stop: the driver's goodbye (last
    /// commands, STOP, CLOSE), which it had written already, cut by `framer`
    /// and handed frame by frame to `obey`, until nothing comes within
    /// `quiet` (ten reads at most: a driver may still be talking). So
    /// nothing the driver sent is lost with the line.
    ///
    /// # Errors
    ///
    /// As [`EmuLine::recv`], or the first error of `obey`.
    pub fn obey_leftover<C: Codec>(
        &mut self,
        baud: u32,
        quiet: Duration,
        framer: &mut Framer<C>,
        mut obey: impl FnMut(&mut EmuLine, C::Frame) -> std::io::Result<()>,
    ) -> std::io::Result<()> {
        let mut buf = [0u8; 512];
        for _ in 0..10 {
            let LineEvent::Received(n) = self.recv(&mut buf, baud, quiet)? else {
                break;
            };
            framer.push(&buf[..n]);
            while let Some(frame) = framer.next_frame() {
                obey(self, frame)?;
            }
        }
        Ok(())
    }

    /// Waits up to `timeout` for bytes from the driver that a device at
    /// `baud` can read (any rate at all when `baud` is 0: a USB device), and
    /// runs the unplug plan.
    ///
    /// # Errors
    ///
    /// A failed read, or a failure to plug back in.
    pub fn recv(
        &mut self,
        buf: &mut [u8],
        baud: u32,
        timeout: Duration,
    ) -> std::io::Result<LineEvent> {
        if let Some(at) = self.unplugged_at {
            let back = self.faults.replug_after.map(|d| at + d);
            match back {
                Some(t) if Instant::now() >= t => {
                    let mut pty = Pty::open()?;
                    pty.link(&self.link)?;
                    tracing::warn!("fault: device plugged back in at {}", self.link.display());
                    self.pty = Some(pty);
                    self.unplugged_at = None;
                    self.plugged_at = Instant::now();
                    self.pacer = Pacer::new();
                    return Ok(LineEvent::Replugged);
                }
                _ => {
                    let wait = back.map_or(timeout, |t| {
                        t.saturating_duration_since(Instant::now()).min(timeout)
                    });
                    std::thread::sleep(wait);
                    return Ok(LineEvent::Unplugged);
                }
            }
        }
        if let Some(after) = self.faults.unplug_after {
            if self.plugged_at.elapsed() >= after {
                tracing::warn!("fault: device unplugged from {}", self.link.display());
                self.pty = None;
                self.unplugged_at = Some(Instant::now());
                // Unplug once per plan: the next plug stays in.
                self.faults.unplug_after = None;
                return Ok(LineEvent::Unplugged);
            }
        }
        let Some(pty) = self.pty.as_mut() else {
            return Ok(LineEvent::Unplugged);
        };
        let timeout = match self.faults.unplug_after {
            Some(after) => timeout.min(after.saturating_sub(self.plugged_at.elapsed())),
            None => timeout,
        };
        let n = pty.recv(buf, timeout)?;
        if n == 0 {
            return Ok(LineEvent::Idle);
        }
        if self.faults.mute {
            return Ok(LineEvent::Idle);
        }
        let line = pty.line_baud();
        if baud != 0 && line != baud {
            self.wrong_baud += n as u64;
            tracing::debug!("{n} bytes at {line} baud: garbage to a device at {baud}");
            return Ok(LineEvent::Idle);
        }
        self.last_heard = Instant::now();
        self.barked = false;
        if let Some(r) = &mut self.recorder {
            r.record(true, &buf[..n], baud);
        }
        Ok(LineEvent::Received(n))
    }

    /// Sends `frame` at `baud`, through the faults, taking the time the line
    /// takes. Nothing goes out while unplugged or muted.
    ///
    /// # Errors
    ///
    /// A failed write.
    pub fn send(&mut self, frame: &[u8], baud: u32) -> std::io::Result<()> {
        if self.faults.mute {
            return Ok(());
        }
        let Some(pty) = self.pty.as_mut() else {
            return Ok(());
        };
        let bytes = self.faults.apply(frame, &mut self.rng, &mut self.injected);
        if let Some(r) = &mut self.recorder {
            r.record(false, &bytes, baud);
        }
        self.pacer.send(pty, &bytes, baud)
    }

    /// A firmware watchdog's trigger: true once each time nothing has come
    /// from the driver for `limit` (logged as the robot stopping).
    pub fn watchdog(&mut self, limit: Duration) -> bool {
        if self.barked || self.last_heard.elapsed() <= limit {
            return false;
        }
        self.barked = true;
        tracing::warn!(
            "watchdog: nothing from the client for {} s; wheels stopped",
            limit.as_secs_f64()
        );
        true
    }

    /// When what was sent has left the line.
    pub fn idle_at(&self) -> Instant {
        self.pacer.idle_at()
    }

    /// A span carrying what the line counted — bytes at the wrong rate and
    /// the faults injected — for an emulator's last log line to be entered
    /// in, so each device logs its own counts beside these.
    pub fn counts_span(&self) -> tracing::Span {
        let n = &self.injected;
        tracing::info_span!(
            "line",
            wrong_baud_bytes = self.wrong_baud,
            noise = n.noise,
            dropped = n.dropped,
            corrupted = n.corrupted,
            truncated = n.truncated
        )
    }

    /// True while plugged in.
    pub fn plugged(&self) -> bool {
        self.pty.is_some()
    }
}
