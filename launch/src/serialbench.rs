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
    #[arg(long, default_value_t = 5.0)]
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
    let (mut connect, mut version, mut first) = (0.0, None, None);
    let mut scans = 0u64;
    let mut values;
    let deadline = Instant::now() + Duration::from_secs(30) + Duration::from_secs_f64(seconds);
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        match line.updates().recv_timeout(left) {
            Ok(urg::Update::Ready { version: v, .. }) => {
                connect = t0.elapsed().as_secs_f64();
                version = Some(v);
            }
            Ok(urg::Update::Scan(readings)) => {
                values = readings.len();
                match first {
                    None => first = Some(Instant::now()),
                    Some(f) => {
                        scans += 1;
                        if f.elapsed().as_secs_f64() >= seconds {
                            break;
                        }
                    }
                }
            }
            Ok(urg::Update::Lost(why)) => anyhow::bail!("urglaser at {baud} baud: {why}"),
            Err(_) => anyhow::bail!("urglaser at {baud} baud: no scans within the deadline"),
        }
    }
    let elapsed = first.map_or(1.0, |f| f.elapsed().as_secs_f64());
    line.stop(urg::Order::Stop);
    emu.stop()?;
    let version = version.ok_or_else(|| anyhow::anyhow!("scans before the URG was ready"))?;
    Ok((scans as f64 / elapsed, connect, values, version))
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
    let rx = line.updates();
    let mut connect = None;
    let mut first = None;
    let mut scans = 0u64;
    let mut values;
    let deadline = Instant::now() + Duration::from_secs(30) + Duration::from_secs_f64(seconds);
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        match rx.recv_timeout(left) {
            Ok(Update::Ready { .. }) => connect = Some(t0.elapsed().as_secs_f64()),
            Ok(Update::Scan(raw, _)) => {
                values = raw.values.len();
                match first {
                    None => first = Some(Instant::now()),
                    Some(f) => {
                        scans += 1;
                        if f.elapsed().as_secs_f64() >= seconds {
                            break;
                        }
                    }
                }
            }
            Ok(Update::Lost(why)) => anyhow::bail!("{baud} baud: {why}"),
            Ok(_) => {}
            Err(_) => anyhow::bail!("{baud} baud: no scans within the deadline"),
        }
    }
    let elapsed = first.map_or(1.0, |f| f.elapsed().as_secs_f64());
    line.stop(device::Order::Stop);
    emu.stop()?;
    Ok((scans as f64 / elapsed, connect.unwrap_or(0.0), values))
}
