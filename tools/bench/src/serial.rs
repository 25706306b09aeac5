//! `troupe bench serial`: scan rates of the sicklms200 and urglaser drivers
//! against their emulated scanners, over a pseudo-terminal paced at the
//! line's baud rate.

use std::time::{Duration, Instant};

use clap::Args;
use troupe_geom::Room;
use troupe_node::Waker;
use troupe_serial::{Emulator, Faults, LineOptions};
use troupe_sicklms200::device::{self, Settings, Update};
use troupe_sicklms200::emulator;

#[derive(Debug, Args)]
pub struct SerialBenchArgs {
    /// Seconds of scans measured per case (after the connection).
    #[arg(long, default_value_t = 5.0, value_name = "SECS", value_parser = troupe_node::args::seconds)]
    pub seconds: f64,
}

/// Runs every case and prints one line each.
pub fn run(a: &SerialBenchArgs) -> anyhow::Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "sicklms200 against its emulator (line time paced at the baud rate; LMS200 mirror 75 Hz)"
    )?;
    writeln!(
        out,
        "{:>8} {:>6} {:>7} {:>10} {:>12}",
        "baud", "res", "values", "scans/s", "connect s"
    )?;
    for baud in [38400u32, 500000] {
        for res in [100u16, 50] {
            let (rate, connect, values) = case(baud, res, a.seconds)?;
            writeln!(
                out,
                "{baud:>8} {:>5}° {values:>7} {rate:>10.1} {connect:>12.2}",
                f64::from(res) / 100.0
            )?;
        }
    }
    writeln!(
        out,
        "urglaser against its emulator (URG-04LX, mirror 600 rpm; RS-232 paced at the baud rate, USB at 12 Mbit/s)"
    )?;
    writeln!(
        out,
        "{:>8} {:>8} {:>7} {:>10} {:>12}",
        "line", "protocol", "values", "scans/s", "connect s"
    )?;
    for baud in [19200u32, 57600, 115200, 0] {
        let (rate, connect, values, version) = urg_case(baud, a.seconds)?;
        let line = if baud == 0 {
            "USB".to_owned()
        } else {
            baud.to_string()
        };
        writeln!(
            out,
            "{line:>8} {:>8} {values:>7} {rate:>10.1} {connect:>12.2}",
            version.to_string().replace(' ', "")
        )?;
    }
    Ok(())
}

/// What a line thread's update means to a rate measurement.
enum Seen {
    /// Connected (the update's own details aside).
    Ready,
    /// A scan of this many values.
    Scan(usize),
    /// The session ended, for this reason.
    Lost(String),
    /// Nothing the measurement counts.
    Other,
}

/// Scans per second over `seconds` after the first scan, seconds from
/// `t0` to the connection, and values per scan, from a line thread's
/// updates as `see` reads them.
fn scan_rate<U>(
    what: &str,
    updates: &std::sync::mpsc::Receiver<U>,
    t0: Instant,
    seconds: f64,
    mut see: impl FnMut(U) -> Seen,
) -> anyhow::Result<(f64, f64, usize)> {
    let (mut connect, mut first, mut scans) = (0.0, None, 0u64);
    let deadline = Instant::now() + Duration::from_secs(30) + Duration::from_secs_f64(seconds);
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        let Ok(u) = updates.recv_timeout(left) else {
            anyhow::bail!("{what}: no scans within the deadline");
        };
        match see(u) {
            Seen::Ready => connect = t0.elapsed().as_secs_f64(),
            Seen::Scan(values) => match first {
                None => first = Some(Instant::now()),
                Some(f) => {
                    scans += 1;
                    let elapsed = f.elapsed().as_secs_f64();
                    if elapsed >= seconds {
                        return Ok((scans as f64 / elapsed, connect, values));
                    }
                }
            },
            Seen::Lost(why) => anyhow::bail!("{what}: {why}"),
            Seen::Other => {}
        }
    }
}

fn case(baud: u32, res: u16, seconds: f64) -> anyhow::Result<(f64, f64, usize)> {
    let emu = Emulator::spawn("bench-serial", |link, stop, linked| {
        let opts = LineOptions {
            link,
            faults: Faults::default(),
            seed: 1,
            capture: None,
        };
        emulator::run_with(&opts, &mut Room, stop, linked)
    })?;
    let settings = Settings::scan_180(emu.link().to_owned(), res, baud);
    let t0 = Instant::now();
    let line = device::spawn(settings, Waker::none())?;
    let measured = scan_rate(
        &format!("{baud} baud"),
        line.updates(),
        t0,
        seconds,
        |u| match u {
            Update::Ready { .. } => Seen::Ready,
            Update::Scan(raw, _) => Seen::Scan(raw.values.len()),
            Update::Lost(why) => Seen::Lost(why),
            Update::Configured(_) => Seen::Other,
        },
    )?;
    line.stop(device::Order::Stop);
    emu.stop()?;
    Ok(measured)
}

/// The urglaser's line thread against the emulated URG, over RS-232 at
/// `baud` or over USB (0): scans per second, seconds to connect, values
/// per scan and the protocol spoken.
fn urg_case(
    baud: u32,
    seconds: f64,
) -> anyhow::Result<(f64, f64, usize, troupe_urglaser::scip::Version)> {
    use troupe_urglaser::{device as urg, emulator as urg_emu};
    let usb = baud == 0;
    let emu = Emulator::spawn("bench-urg", move |link, stop, linked| {
        let opts = urg_emu::EmulatorOptions {
            line: LineOptions {
                link,
                faults: Faults::default(),
                seed: 1,
                capture: None,
            },
            usb,
        };
        urg_emu::run_with(&opts, &mut Room, stop, linked)
    })?;
    let settings = urg::Settings {
        port: emu.link().to_owned(),
        serial: !usb,
        baud: if usb { 115200 } else { baud },
    };
    let t0 = Instant::now();
    let line = urg::spawn(settings, Waker::none())?;
    let mut version = None;
    let what = format!("urglaser at {baud} baud");
    let (rate, connect, values) = scan_rate(&what, line.updates(), t0, seconds, |u| match u {
        urg::Update::Ready { version: v, .. } => {
            version = Some(v);
            Seen::Ready
        }
        urg::Update::Scan(readings) => Seen::Scan(readings.len()),
        urg::Update::Lost(why) => Seen::Lost(why),
    })?;
    line.stop(urg::Order::Stop);
    emu.stop()?;
    let version = version.ok_or_else(|| anyhow::anyhow!("scans before the URG was ready"))?;
    Ok((rate, connect, values, version))
}
