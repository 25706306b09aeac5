//! `troupe bench bridge --hostile`: well-behaved Player clients beside
//! hostile ones (issue 70's table).
//!
//! On one robot port, 50 clients as libplayerc reads: PULL mode,
//! position2d and the laser opened, a `Read()` (REQ DATA to SYNCH) and a
//! GET_GEOM every 100 ms. A quiet row, then a row with each of the hostile
//! in turn beside them: 1,000 connections that send nothing, 50 clients
//! that opened the laser and never read, one client writing 1,000,000
//! requests without reading, one adding 100,000 replace rules without
//! reading, and 100 connections of random bytes. For each row: the good
//! clients' p99 request time against the quiet row's (target at most 2x),
//! their reads that brought data and the overflows (no loss), this
//! process's memory (the bridge runs in it, as in the launcher's) above
//! the quiet row's (target: under 100 MB), and whether a new client is
//! served afterwards.

use std::io::Write;
use std::net::{Shutdown, SocketAddr, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Barrier, Mutex};
use std::time::{Duration, Instant};

use troupe_bridge::wire::{self, player};
use troupe_msgs::Interface;

use crate::harness::{percentile, status_mb, us};
use crate::raw_player::{connect, header, open, player_req, pull_round, req, request};

/// What the good clients saw in one row.
#[derive(Default)]
struct Seen {
    times: Vec<Duration>,
    reads: usize,
    with_data: usize,
    overflows: usize,
    failed: usize,
}

/// One well-behaved client: connected, then (once the hostile ones are in)
/// reading for `seconds`.
fn good(addr: SocketAddr, phase: Duration, seconds: f64, all_in: &Barrier) -> anyhow::Result<Seen> {
    let opened = connect(addr).and_then(|mut s| {
        open(&mut s, Interface::Position2d)?;
        open(&mut s, Interface::Laser)?;
        Ok(s)
    });
    all_in.wait();
    all_in.wait();
    let mut s = opened?;
    let mut seen = Seen::default();
    let geom = req(Interface::Position2d, 1);
    let start = Instant::now();
    let mut due = start + phase;
    while start.elapsed().as_secs_f64() < seconds {
        // Pacing the client, not synchronising with anything.
        std::thread::sleep(due.saturating_duration_since(Instant::now()));
        due += Duration::from_millis(100);
        let t0 = Instant::now();
        let round = pull_round(&mut s)?;
        seen.times.push(t0.elapsed());
        seen.reads += 1;
        seen.overflows += usize::from(round.overflow);
        seen.with_data += usize::from(round.data);
        let t0 = Instant::now();
        match request(&mut s, geom, &[]) {
            Ok(_) => seen.times.push(t0.elapsed()),
            Err(_) => seen.failed += 1,
        }
    }
    Ok(seen)
}

/// The hostile clients of a row, started; stopped by `stop`.
type Attack = Box<dyn Fn(SocketAddr, Arc<AtomicBool>) -> anyhow::Result<Vec<TcpStream>>>;

fn attacks() -> Vec<(&'static str, Attack)> {
    vec![
        (
            "+ 1,000 idle connections",
            Box::new(|addr, _| {
                // Each connects and sends nothing; those past the cap are closed.
                Ok((0..1000)
                    .filter_map(|_| TcpStream::connect(addr).ok())
                    .collect())
            }),
        ),
        (
            "+ 50 clients that never read the laser",
            Box::new(|addr, _| {
                (0..50)
                    .map(|_| {
                        let mut s = connect(addr)?;
                        request(
                            &mut s,
                            player_req(player::REQ_DATAMODE),
                            &player::PUSH.to_be_bytes(),
                        )?;
                        open(&mut s, Interface::Laser)?;
                        open(&mut s, Interface::Position2d)?;
                        Ok(s)
                    })
                    .collect()
            }),
        ),
        (
            "+ 1 client writing 1,000,000 requests",
            Box::new(|addr, stop| {
                let mut s = connect(addr)?;
                open(&mut s, Interface::Position2d)?;
                let keep = s.try_clone()?;
                let one = wire::message(header(req(Interface::Position2d, 1)), &[]);
                let many: Vec<u8> = one
                    .iter()
                    .copied()
                    .cycle()
                    .take(one.len() * 10_000)
                    .collect();
                std::thread::spawn(move || {
                    for _ in 0..100 {
                        if stop.load(Ordering::Relaxed) || s.write_all(&many).is_err() {
                            break;
                        }
                    }
                });
                Ok(vec![keep])
            }),
        ),
        (
            "+ 1 client adding 100,000 replace rules",
            Box::new(|addr, stop| {
                let mut s = connect(addr)?;
                let keep = s.try_clone()?;
                std::thread::spawn(move || {
                    let mut batch = Vec::new();
                    for i in 0..100_000i32 {
                        let mut body = Vec::new();
                        for v in [4, i, 1, -1, 1] {
                            body.extend_from_slice(&v.to_be_bytes());
                        }
                        batch.extend(wire::message(
                            header(player_req(player::REQ_ADD_REPLACE_RULE)),
                            &body,
                        ));
                        if batch.len() > 64 * 1024 {
                            if stop.load(Ordering::Relaxed) || s.write_all(&batch).is_err() {
                                return;
                            }
                            batch.clear();
                        }
                    }
                });
                Ok(vec![keep])
            }),
        ),
        (
            "+ 100 connections of random bytes",
            Box::new(|addr, _| {
                let mut seed = 0x2545_F491_4F6C_DD1Du64;
                let mut noise = vec![0u8; 64 * 1024];
                (0..100)
                    .map(|_| {
                        for b in &mut noise {
                            seed ^= seed << 13;
                            seed ^= seed >> 7;
                            seed ^= seed << 17;
                            *b = seed as u8;
                        }
                        let mut s = TcpStream::connect(addr)?;
                        // The bridge may close it at the first bad header.
                        let _ = s.write_all(&noise);
                        Ok(s)
                    })
                    .collect()
            }),
        ),
    ]
}

/// Whether a new client is answered its DEVLIST.
fn serving(addr: SocketAddr) -> bool {
    connect(addr)
        .and_then(|mut s| request(&mut s, player_req(player::REQ_DEVLIST), &[]).map(drop))
        .is_ok()
}

/// Runs the rows against the bridge at `addr` and prints the table.
pub(crate) fn run(addr: SocketAddr, seconds: f64, out: &mut impl Write) -> anyhow::Result<()> {
    const GOOD: usize = 50;
    writeln!(
        out,
        "troupe bench bridge --hostile: {GOOD} clients (PULL, position2d and laser, a Read() and a GET_GEOM every 100 ms) beside hostile ones, {seconds} s a row"
    )?;
    writeln!(
        out,
        "  {:<42} {:>9} {:>9} {:>8} {:>14} {:>9} {:>10} {:>8}",
        "", "p50", "p99", "p99/quiet", "reads w/ data", "overflows", "RSS +MB", "serving"
    )?;
    let mut quiet_p99 = None;
    let mut quiet_rss = 0.0;
    let mut rows: Vec<(&str, Option<Attack>)> = vec![("quiet", None)];
    rows.extend(attacks().into_iter().map(|(n, a)| (n, Some(a))));
    for (name, attack) in rows {
        let stop = Arc::new(AtomicBool::new(false));
        // The good clients connect first; the hostile ones come while
        // they are in; then the good ones read.
        let all_in = Arc::new(Barrier::new(GOOD + 1));
        let clients: Vec<_> = (0..GOOD)
            .map(|i| {
                let phase = Duration::from_millis(100) * i as u32 / GOOD as u32;
                let all_in = all_in.clone();
                std::thread::spawn(move || good(addr, phase, seconds, &all_in))
            })
            .collect();
        all_in.wait();
        let held = match &attack {
            Some(a) => a(addr, stop.clone()),
            None => Ok(Vec::new()),
        };
        all_in.wait();
        let held = held?;
        let peak = Arc::new(Mutex::new(status_mb("VmRSS:")));
        let watching = Arc::new(AtomicBool::new(true));
        let watcher = {
            let (peak, watching) = (peak.clone(), watching.clone());
            std::thread::spawn(move || {
                while watching.load(Ordering::Relaxed) {
                    let now = status_mb("VmRSS:");
                    let mut p = peak.lock().unwrap_or_else(|e| e.into_inner());
                    *p = p.max(now);
                    drop(p);
                    std::thread::sleep(Duration::from_millis(50));
                }
            })
        };
        let mut seen = Seen::default();
        for c in clients {
            let s = c
                .join()
                .map_err(|_| anyhow::anyhow!("a client thread panicked"))??;
            seen.times.extend(s.times);
            seen.reads += s.reads;
            seen.with_data += s.with_data;
            seen.overflows += s.overflows;
            seen.failed += s.failed;
        }
        watching.store(false, Ordering::Relaxed);
        let _ = watcher.join();
        stop.store(true, Ordering::Relaxed);
        for s in &held {
            let _ = s.shutdown(Shutdown::Both);
        }
        drop(held);
        let ok = serving(addr);
        seen.times.sort();
        let p99 = percentile(&seen.times, 0.99);
        let peak = *peak.lock().unwrap_or_else(|e| e.into_inner());
        let base = *quiet_p99.get_or_insert(p99);
        if name == "quiet" {
            quiet_rss = peak;
        }
        writeln!(
            out,
            "  {name:<42} {:>9} {:>9} {:>8.2}x {:>8}/{:<5} {:>9} {:>10.1} {:>8}{}",
            us(percentile(&seen.times, 0.5)),
            us(p99),
            p99.as_secs_f64() / base.as_secs_f64().max(1e-9),
            seen.with_data,
            seen.reads,
            seen.overflows,
            peak - quiet_rss,
            if ok { "yes" } else { "NO" },
            if seen.failed > 0 {
                format!("  ({} GET_GEOM failed)", seen.failed)
            } else {
                String::new()
            },
        )?;
    }
    writeln!(
        out,
        "  targets: p99 at most 2x the quiet row's, every read with data and no overflow, memory under 100 MB above quiet, serving after each"
    )?;
    Ok(())
}
