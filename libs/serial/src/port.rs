//! A serial device in raw mode.

use std::fs::{File, OpenOptions};
use std::io::{Read, Write};
use std::os::fd::AsFd;
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use nix::fcntl::OFlag;
use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use nix::sys::termios::{self, FlushArg};

/// Why a line could not be used.
#[derive(Debug, thiserror::Error)]
pub enum LineError {
    /// The device could not be opened or configured.
    #[error("cannot open {path}: {source}")]
    Open {
        /// The device path.
        path: PathBuf,
        /// What the system said.
        source: std::io::Error,
    },
    /// The baud rate is not one the line can be set to.
    #[error("the line cannot be set to {0} baud")]
    Baud(u32),
    /// The device went away (unplugged, or the emulator closed its end).
    #[error("{path}: device lost: {reason}")]
    Lost {
        /// The device path.
        path: PathBuf,
        /// What the system said.
        reason: String,
    },
}

/// The standard rates: what drivers that try several rates choose among.
/// A [`Port`] also takes any other rate the line supports (Linux sets it
/// exactly on a pseudo-terminal, and as near as its divisor allows on a
/// UART): the White Box 914's 416666 baud, say.
pub const BAUD_RATES: [u32; 10] = [
    2400, 4800, 9600, 19200, 38400, 57600, 115200, 230400, 460800, 500000,
];

/// Stop bits per character.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum StopBits {
    /// 8N1, what almost every device speaks.
    #[default]
    One,
    /// 8N2.
    Two,
}

/// Puts `fd` in raw 8-bit, no-parity mode at `baud` with `stop` stop bits,
/// receiver on, modem lines ignored.
pub(crate) fn configure(fd: impl AsFd, baud: u32, stop: StopBits) -> Result<(), std::io::Error> {
    use rustix::termios::{self, ControlModes, OptionalActions};
    let bad = || std::io::Error::other(LineError::Baud(baud));
    if baud == 0 {
        return Err(bad());
    }
    let mut t = termios::tcgetattr(fd.as_fd())?;
    t.make_raw();
    t.control_modes |= ControlModes::CLOCAL | ControlModes::CREAD;
    t.control_modes &= !(ControlModes::CSTOPB | ControlModes::PARENB | ControlModes::CRTSCTS);
    if stop == StopBits::Two {
        t.control_modes |= ControlModes::CSTOPB;
    }
    t.set_speed(baud).map_err(|_| bad())?;
    termios::tcsetattr(fd.as_fd(), OptionalActions::Now, &t).map_err(|e| match e {
        rustix::io::Errno::INVAL => bad(),
        e => e.into(),
    })?;
    Ok(())
}

/// The output rate `fd` is set to (0 if it cannot be read).
pub(crate) fn baud_of(fd: impl AsFd) -> u32 {
    rustix::termios::tcgetattr(fd.as_fd()).map_or(0, |t| t.output_speed())
}

/// A serial device (a real one or a pseudo-terminal's slave), raw 8N1.
#[derive(Debug)]
pub struct Port {
    file: File,
    path: PathBuf,
    baud: u32,
    stop: StopBits,
}

impl Port {
    /// Opens `path` (following symlinks) at `baud`, raw, and empties its queues.
    ///
    /// # Errors
    ///
    /// [`LineError::Open`] when the device is missing, busy or not a
    /// terminal; [`LineError::Baud`] for a rate the line cannot take.
    pub fn open(path: &Path, baud: u32) -> Result<Port, LineError> {
        let open = |source| LineError::Open {
            path: path.to_owned(),
            source,
        };
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .custom_flags(OFlag::O_NOCTTY.bits())
            .open(path)
            .map_err(open)?;
        configure(&file, baud, StopBits::One).map_err(|e| match e.downcast::<LineError>() {
            Ok(baud) => baud,
            Err(e) => open(e),
        })?;
        let port = Port {
            file,
            path: path.to_owned(),
            baud,
            stop: StopBits::One,
        };
        port.discard_input();
        Ok(port)
    }

    /// The device path, as given.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The current baud rate.
    pub fn baud(&self) -> u32 {
        self.baud
    }

    /// Changes the line's baud rate.
    ///
    /// # Errors
    ///
    /// [`LineError::Baud`] for a rate the line cannot take, [`LineError::Lost`] if the
    /// device refused.
    pub fn set_baud(&mut self, baud: u32) -> Result<(), LineError> {
        self.reconfigure(baud, self.stop)
    }

    /// Changes the line's stop bits.
    ///
    /// # Errors
    ///
    /// [`LineError::Lost`] if the device refused.
    pub fn set_stop_bits(&mut self, stop: StopBits) -> Result<(), LineError> {
        self.reconfigure(self.baud, stop)
    }

    fn reconfigure(&mut self, baud: u32, stop: StopBits) -> Result<(), LineError> {
        configure(&self.file, baud, stop).map_err(|e| match e.downcast::<LineError>() {
            Ok(baud) => baud,
            Err(e) => self.lost(e),
        })?;
        self.baud = baud;
        self.stop = stop;
        Ok(())
    }

    /// Drops whatever the device sent that has not been read (Player's
    /// drivers do this before each request).
    pub fn discard_input(&self) {
        // A pseudo-terminal whose master is gone refuses; the next read says so.
        let _ = termios::tcflush(self.file.as_fd(), FlushArg::TCIFLUSH);
    }

    /// Writes all of `bytes` and waits until they are on the line.
    ///
    /// # Errors
    ///
    /// [`LineError::Lost`] when the device is gone.
    pub fn send(&mut self, bytes: &[u8]) -> Result<(), LineError> {
        self.file.write_all(bytes).map_err(|e| self.lost(e))?;
        // tcdrain on a pseudo-terminal returns at once; on a UART it waits
        // for the shift register, as Player's drivers do.
        let _ = termios::tcdrain(self.file.as_fd());
        Ok(())
    }

    /// Reads what is available into `buf`, waiting up to `timeout` for the
    /// first byte. `Ok(0)` means nothing came in time.
    ///
    /// # Errors
    ///
    /// [`LineError::Lost`] when the device hung up or the read failed.
    pub fn recv(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, LineError> {
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let ms = PollTimeout::try_from(left.as_millis().min(60_000) as u32)
                .unwrap_or(PollTimeout::MAX);
            let mut fds = [PollFd::new(self.file.as_fd(), PollFlags::POLLIN)];
            match poll(&mut fds, ms) {
                Ok(0) => return Ok(0),
                Ok(_) => {}
                Err(nix::errno::Errno::EINTR) => continue,
                Err(e) => return Err(self.lost(e.into())),
            }
            let revents = fds[0].revents().unwrap_or(PollFlags::empty());
            if revents.contains(PollFlags::POLLIN) {
                return match self.file.read(buf) {
                    Ok(0) => Err(self.lost(std::io::Error::other("end of file"))),
                    Ok(n) => Ok(n),
                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                    Err(e) => Err(self.lost(e)),
                };
            }
            if revents.intersects(PollFlags::POLLHUP | PollFlags::POLLERR | PollFlags::POLLNVAL) {
                return Err(self.lost(std::io::Error::other("hung up")));
            }
            if Instant::now() >= deadline {
                return Ok(0);
            }
        }
    }

    fn lost(&self, e: std::io::Error) -> LineError {
        LineError::Lost {
            path: self.path.clone(),
            reason: e.to_string(),
        }
    }
}
