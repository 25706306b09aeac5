//! Pseudo-terminals for device emulators.

use std::fs::File;
use std::io::{Read, Write};
use std::os::fd::{AsFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use nix::fcntl::{fcntl, FcntlArg, OFlag};
use nix::poll::{poll, PollFd, PollFlags, PollTimeout};

use crate::port::{baud_of, configure, StopBits};

/// A pseudo-terminal: the emulator holds the master, a driver opens the
/// slave (through [`Pty::link`]'s symlink) as it would a serial port.
///
/// The emulator also keeps the slave open, so the line survives a driver
/// closing and reopening it, and so it can read the baud rate the driver set
/// ([`Pty::line_baud`]) — a real device only understands bytes sent at its
/// own rate.
#[derive(Debug)]
pub struct Pty {
    master: File,
    slave: OwnedFd,
    slave_path: PathBuf,
    link: Option<PathBuf>,
    dropped: u64,
}

impl Pty {
    /// Opens a new pseudo-terminal, raw at 9600 baud.
    ///
    /// # Errors
    ///
    /// What the system says when no pseudo-terminal can be had.
    pub fn open() -> std::io::Result<Pty> {
        let pair = nix::pty::openpty(None, None)?;
        configure(&pair.slave, 9600, StopBits::One)?;
        let slave_path = nix::unistd::ttyname(&pair.slave)?;
        // A device writes whether or not anyone listens: never block on a
        // full buffer, drop instead (see `dropped`).
        let flags = OFlag::from_bits_truncate(fcntl(&pair.master, FcntlArg::F_GETFL)?);
        fcntl(&pair.master, FcntlArg::F_SETFL(flags | OFlag::O_NONBLOCK))?;
        Ok(Pty {
            master: File::from(pair.master),
            slave: pair.slave,
            slave_path,
            link: None,
            dropped: 0,
        })
    }

    /// The slave's device path (`/dev/pts/N`).
    pub fn slave_path(&self) -> &Path {
        &self.slave_path
    }

    /// Makes `path` a symlink to the slave, replacing an old symlink there
    /// (never a regular file or a real device). Removed on drop.
    ///
    /// # Errors
    ///
    /// When `path` exists and is not a symlink, or cannot be written.
    pub fn link(&mut self, path: &Path) -> std::io::Result<()> {
        if let Ok(meta) = std::fs::symlink_metadata(path) {
            if !meta.file_type().is_symlink() {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::AlreadyExists,
                    format!(
                        "{} exists and is not a symlink; not replacing it",
                        path.display()
                    ),
                ));
            }
            std::fs::remove_file(path)?;
        }
        std::os::unix::fs::symlink(&self.slave_path, path)?;
        self.link = Some(path.to_owned());
        Ok(())
    }

    /// The baud rate the other end last set on the line.
    pub fn line_baud(&self) -> u32 {
        baud_of(self.slave.as_fd())
    }

    /// Reads what the driver wrote, waiting up to `timeout`; `Ok(0)` when
    /// nothing came.
    ///
    /// # Errors
    ///
    /// A failed poll or read.
    pub fn recv(&mut self, buf: &mut [u8], timeout: Duration) -> std::io::Result<usize> {
        let ms = PollTimeout::try_from(timeout.as_millis().min(60_000) as u32)
            .unwrap_or(PollTimeout::MAX);
        let mut fds = [PollFd::new(self.master.as_fd(), PollFlags::POLLIN)];
        match poll(&mut fds, ms) {
            Ok(0) | Err(nix::errno::Errno::EINTR) => return Ok(0),
            Ok(_) => {}
            Err(e) => return Err(e.into()),
        }
        match self.master.read(buf) {
            Ok(n) => Ok(n),
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::Interrupted
                ) =>
            {
                Ok(0)
            }
            Err(e) => Err(e),
        }
    }

    /// Writes `bytes` toward the driver at once; what does not fit in the
    /// line's buffer (nobody reading) is dropped and counted.
    ///
    /// # Errors
    ///
    /// A failed write other than a full buffer.
    pub fn send(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        let mut rest = bytes;
        while !rest.is_empty() {
            match self.master.write(rest) {
                Ok(n) => rest = &rest[n..],
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                    self.dropped += rest.len() as u64;
                    break;
                }
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }

    /// Bytes dropped because nobody read them.
    pub fn dropped(&self) -> u64 {
        self.dropped
    }
}

impl Drop for Pty {
    fn drop(&mut self) {
        if let Some(link) = &self.link {
            if std::fs::read_link(link).ok().as_deref() == Some(self.slave_path.as_path()) {
                let _ = std::fs::remove_file(link);
            }
        }
    }
}

/// Spaces writes as a line at a given baud rate would carry them (10 bits
/// per byte: start, 8 data, stop), so an emulated device is no faster than
/// the real one.
#[derive(Debug, Default)]
pub struct Pacer {
    busy_until: Option<Instant>,
}

impl Pacer {
    /// A pacer with an idle line.
    pub fn new() -> Self {
        Pacer::default()
    }

    /// How long `n` bytes take on the line at `baud`.
    pub fn line_time(n: usize, baud: u32) -> Duration {
        Duration::from_secs_f64(n as f64 * 10.0 / f64::from(baud.max(1)))
    }

    /// Sends `bytes` through `pty` in slices of about a millisecond of line
    /// time each, sleeping so that the last byte leaves when the line would
    /// have carried it.
    ///
    /// # Errors
    ///
    /// What [`Pty::send`] returns.
    pub fn send(&mut self, pty: &mut Pty, bytes: &[u8], baud: u32) -> std::io::Result<()> {
        let per_ms = (baud as usize / 10 / 1000).max(16);
        let now = Instant::now();
        let mut t = match self.busy_until {
            Some(b) if b > now => b,
            _ => now,
        };
        for chunk in bytes.chunks(per_ms) {
            t += Self::line_time(chunk.len(), baud);
            pty.send(chunk)?;
            let now = Instant::now();
            if t > now {
                std::thread::sleep(t - now);
            }
        }
        self.busy_until = Some(t);
        Ok(())
    }

    /// When the line is next free.
    pub fn idle_at(&self) -> Instant {
        self.busy_until.unwrap_or_else(Instant::now)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Port;

    #[test]
    fn a_driver_port_talks_to_the_emulator_through_the_link() {
        let dir = std::env::temp_dir().join(format!("troupe-serial-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let link = dir.join("dev");
        let mut pty = Pty::open().unwrap();
        pty.link(&link).unwrap();
        let mut port = Port::open(&link, 38400).unwrap();
        assert_eq!(pty.line_baud(), 38400);
        port.set_baud(500000).unwrap();
        assert_eq!(pty.line_baud(), 500000);
        // A rate off the standard list (the White Box 914's), 8N2.
        port.set_baud(416_666).unwrap();
        port.set_stop_bits(crate::StopBits::Two).unwrap();
        assert_eq!((pty.line_baud(), port.baud()), (416_666, 416_666));
        assert!(matches!(port.set_baud(0), Err(crate::LineError::Baud(0))));

        port.send(b"hello").unwrap();
        let mut buf = [0u8; 16];
        let n = pty.recv(&mut buf, Duration::from_secs(5)).unwrap();
        assert_eq!(&buf[..n], b"hello");
        pty.send(b"world").unwrap();
        let n = port.recv(&mut buf, Duration::from_secs(5)).unwrap();
        assert_eq!(&buf[..n], b"world");
        // Nothing more: a read times out with 0.
        assert_eq!(port.recv(&mut buf, Duration::from_millis(1)).unwrap(), 0);

        drop(pty);
        assert!(!link.exists(), "the link goes with the emulator");
        assert!(
            port.recv(&mut buf, Duration::from_secs(5)).is_err(),
            "a vanished device is reported as lost"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn link_refuses_to_replace_a_regular_file() {
        let dir = std::env::temp_dir().join(format!("troupe-serial-f-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("plain");
        std::fs::write(&file, b"keep").unwrap();
        let mut pty = Pty::open().unwrap();
        let err = pty.link(&file).unwrap_err();
        assert!(err.to_string().contains("not a symlink"), "{err}");
        assert_eq!(std::fs::read(&file).unwrap(), b"keep");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
