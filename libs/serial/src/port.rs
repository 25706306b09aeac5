//! A serial device in raw mode.

use std::fs::{File, OpenOptions};
use std::io::{Read, Write};
use std::os::fd::AsFd;
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use nix::fcntl::OFlag;
use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use nix::sys::termios::{self, BaudRate, ControlFlags, FlushArg, SetArg};

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
    /// The baud rate is not one a serial line can be set to.
    #[error("baud rate {0} is not supported (try one of 9600, 19200, 38400, 57600, 115200, 230400, 500000)")]
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

/// The baud rates a [`Port`] accepts.
pub const BAUD_RATES: [u32; 10] = [
    2400, 4800, 9600, 19200, 38400, 57600, 115200, 230400, 460800, 500000,
];

/// True when `baud` is one of [`BAUD_RATES`].
pub fn baud_supported(baud: u32) -> bool {
    BAUD_RATES.contains(&baud)
}

fn baud_rate(baud: u32) -> Option<BaudRate> {
    Some(match baud {
        2400 => BaudRate::B2400,
        4800 => BaudRate::B4800,
        9600 => BaudRate::B9600,
        19200 => BaudRate::B19200,
        38400 => BaudRate::B38400,
        57600 => BaudRate::B57600,
        115200 => BaudRate::B115200,
        230400 => BaudRate::B230400,
        460800 => BaudRate::B460800,
        500000 => BaudRate::B500000,
        _ => return None,
    })
}

pub(crate) fn baud_of(speed: BaudRate) -> u32 {
    BAUD_RATES
        .iter()
        .copied()
        .find(|&b| baud_rate(b) == Some(speed))
        .unwrap_or(0)
}

/// Puts `fd` in raw 8N1 mode at `baud`, receiver on, modem lines ignored.
pub(crate) fn configure(fd: impl AsFd, baud: u32) -> Result<(), std::io::Error> {
    let speed = baud_rate(baud).ok_or_else(|| std::io::Error::other(LineError::Baud(baud)))?;
    let mut t = termios::tcgetattr(fd.as_fd())?;
    termios::cfmakeraw(&mut t);
    t.control_flags |= ControlFlags::CLOCAL | ControlFlags::CREAD;
    t.control_flags &= !(ControlFlags::CSTOPB | ControlFlags::PARENB | ControlFlags::CRTSCTS);
    termios::cfsetspeed(&mut t, speed)?;
    termios::tcsetattr(fd.as_fd(), SetArg::TCSANOW, &t)?;
    Ok(())
}

/// A serial device (a real one or a pseudo-terminal's slave), raw 8N1.
#[derive(Debug)]
pub struct Port {
    file: File,
    path: PathBuf,
    baud: u32,
}

impl Port {
    /// Opens `path` (following symlinks) at `baud`, raw, and empties its queues.
    ///
    /// # Errors
    ///
    /// [`LineError::Open`] when the device is missing, busy or not a
    /// terminal; [`LineError::Baud`] for a rate the line cannot take.
    pub fn open(path: &Path, baud: u32) -> Result<Port, LineError> {
        if !baud_supported(baud) {
            return Err(LineError::Baud(baud));
        }
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
        configure(&file, baud).map_err(open)?;
        let port = Port {
            file,
            path: path.to_owned(),
            baud,
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
    /// [`LineError::Baud`] for an unknown rate, [`LineError::Lost`] if the
    /// device refused.
    pub fn set_baud(&mut self, baud: u32) -> Result<(), LineError> {
        if !baud_supported(baud) {
            return Err(LineError::Baud(baud));
        }
        configure(&self.file, baud).map_err(|e| self.lost(e))?;
        self.baud = baud;
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
