//! `troupe bench foxglove`: the Foxglove server under load. The 100-Pioneer
//! world runs in real time (each robot its own port, odometry, sonars and
//! laser); the robots' data rates are counted with no server, with `troupe
//! foxglove` serving no one, and with one client of the protocol subscribed
//! to every channel it advertises. For each: the server's CPU and what the
//! client received. Target (issue 45): the fleet's rates unchanged, the
//! server at most 15% of a core.

use std::collections::HashMap;
use std::io::Write;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use troupe_msgs::Interface;
use troupe_node::{Mode, ZenohArgs};
use tungstenite::client::IntoClientRequest;
use tungstenite::Message;

use crate::harness::{Figures, Kid, Window, ROBOTS};

/// `troupe bench foxglove` options.
#[derive(Debug, clap::Args)]
pub struct FoxgloveBenchArgs {
    /// Seconds measured for each row.
    #[arg(long, default_value_t = 10.0, value_name = "SECS", value_parser = troupe_node::args::seconds)]
    pub seconds: f64,
    /// Where Stage's sample bitmaps are (cave.png).
    #[arg(long, value_name = "DIR")]
    pub bitmaps: Option<std::path::PathBuf>,
}

/// What the client received, counted as it reads.
#[derive(Default)]
struct Received {
    channels: AtomicU64,
    messages: AtomicU64,
    bytes: AtomicU64,
}

/// A client of the protocol: subscribes to every channel as it is
/// advertised (again if the server answers that it does not know it yet)
/// and counts the messages, until `stop`.
fn client(url: &str, stop: &AtomicBool, got: &Received) -> anyhow::Result<()> {
    let mut req = url.into_client_request()?;
    req.headers_mut().insert(
        "Sec-WebSocket-Protocol",
        tungstenite::http::HeaderValue::from_static("foxglove.sdk.v1"),
    );
    let (mut ws, _) = tungstenite::connect(req)?;
    if let tungstenite::stream::MaybeTlsStream::Plain(s) = ws.get_mut() {
        s.set_read_timeout(Some(Duration::from_millis(200)))?;
    }
    // Channel id -> our subscription id.
    let mut subs: HashMap<u64, u64> = HashMap::new();
    while !stop.load(Ordering::Relaxed) {
        let m = match ws.read() {
            Ok(m) => m,
            Err(tungstenite::Error::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                continue
            }
            Err(e) => return Err(e.into()),
        };
        match m {
            Message::Binary(b) if b.first() == Some(&1) => {
                got.messages.fetch_add(1, Ordering::Relaxed);
                got.bytes.fetch_add(b.len() as u64, Ordering::Relaxed);
            }
            Message::Text(t) => {
                let v: serde_json::Value = serde_json::from_str(&t)?;
                let ids: Vec<u64> = match v["op"].as_str() {
                    Some("advertise") => v["channels"]
                        .as_array()
                        .into_iter()
                        .flatten()
                        .filter_map(|c| c["id"].as_u64())
                        .collect(),
                    // Advertised before registered (see the Python test):
                    // subscribe again.
                    Some("status") => v["message"]
                        .as_str()
                        .and_then(|m| m.strip_prefix("Unknown channel ID: "))
                        .and_then(|id| id.parse().ok())
                        .into_iter()
                        .collect(),
                    _ => continue,
                };
                let next = subs.len() as u64 + 1;
                let subscriptions: Vec<serde_json::Value> = ids
                    .iter()
                    .enumerate()
                    .map(|(k, &ch)| {
                        let id = *subs.entry(ch).or_insert(next + k as u64);
                        serde_json::json!({"id": id, "channelId": ch})
                    })
                    .collect();
                got.channels.store(subs.len() as u64, Ordering::Relaxed);
                let sub = serde_json::json!({"op": "subscribe", "subscriptions": subscriptions});
                ws.send(Message::text(sub.to_string()))?;
            }
            _ => {}
        }
    }
    let _ = ws.close(None);
    Ok(())
}

/// Runs `troupe bench foxglove`.
pub fn run(a: &FoxgloveBenchArgs) -> anyhow::Result<()> {
    let bitmaps = crate::harness::stage_bitmaps(a.bitmaps.as_deref())?;
    let dir = std::env::temp_dir().join(format!("troupe-bench-foxglove-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let result = measure(a, &bitmaps, &dir);
    let _ = std::fs::remove_dir_all(&dir);
    result
}

fn row(
    out: &mut impl Write,
    who: &str,
    f: &Figures,
    got: Option<(u64, f64, f64)>,
) -> anyhow::Result<()> {
    let cpu = if who.starts_with("no server") {
        "-".to_owned()
    } else {
        format!("{:.1}%", 100.0 * f.cpu)
    };
    let (channels, msgs, mb) = got.map_or(("-".into(), "-".into(), "-".into()), |(c, m, b)| {
        (c.to_string(), format!("{m:.0}"), format!("{b:.2}"))
    });
    writeln!(
        out,
        "  {who:<30}  {cpu:>15}  {:>17.2}  {:>16.0}  {channels:>8}  {msgs:>10}  {mb:>7}",
        f.odometry, f.ranges
    )?;
    out.flush()?;
    Ok(())
}

fn measure(
    a: &FoxgloveBenchArgs,
    bitmaps: &std::path::Path,
    dir: &std::path::Path,
) -> anyhow::Result<()> {
    let (launcher, router) = crate::harness::p100_stack(dir, bitmaps, 1.0)?;
    let launcher = Kid(launcher);
    let z = ZenohArgs {
        connect: vec![router.clone()],
        no_multicast: true,
        ..Default::default()
    };
    // The robots' data, counted.
    let session = z.open(Mode::Client)?;
    let (_odo, odometry) = crate::harness::count(&session, Interface::Position2d)?;
    let (_rng, ranges) = crate::harness::count(&session, Interface::Ranger)?;
    let window = || Duration::from_secs_f64(a.seconds);

    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "troupe bench foxglove: {ROBOTS} Pioneers in real time (odometry, 16 sonars, 180-beam laser each), {} s per row",
        a.seconds
    )?;
    writeln!(
        out,
        "  {:<30}  {:>15}  {:>17}  {:>16}  {:>8}  {:>10}  {:>7}",
        "",
        "server CPU",
        "odometry Hz/robot",
        "ranger samples/s",
        "channels",
        "client msg/s",
        "MB/s"
    )?;

    let w = Window::start(None, &odometry, &ranges);
    std::thread::sleep(window());
    row(&mut out, "no server", &w.end(&odometry, &ranges), None)?;

    let (server, url) =
        crate::harness::server(&router, &["foxglove", "--port", "0"], "troupe foxglove: ")?;
    let url = url.split_whitespace().next().unwrap_or_default().to_owned();
    // Its devices found and their setup asked (maps, geometry, the world).
    std::thread::sleep(Duration::from_secs(3));
    let w = Window::start(Some(server.0.id()), &odometry, &ranges);
    std::thread::sleep(window());
    row(
        &mut out,
        "troupe foxglove, no client",
        &w.end(&odometry, &ranges),
        None,
    )?;

    let stop = Arc::new(AtomicBool::new(false));
    let got = Arc::new(Received::default());
    let reader = {
        let (stop, got) = (stop.clone(), got.clone());
        std::thread::spawn(move || client(&url, &stop, &got))
    };
    // Subscribed to what was advertised, latched messages delivered.
    std::thread::sleep(Duration::from_secs(3));
    let (m0, b0) = (
        got.messages.load(Ordering::Relaxed),
        got.bytes.load(Ordering::Relaxed),
    );
    let w = Window::start(Some(server.0.id()), &odometry, &ranges);
    std::thread::sleep(window());
    let f = w.end(&odometry, &ranges);
    let (m1, b1) = (
        got.messages.load(Ordering::Relaxed),
        got.bytes.load(Ordering::Relaxed),
    );
    stop.store(true, Ordering::Relaxed);
    reader
        .join()
        .map_err(|_| anyhow::anyhow!("the client panicked"))??;
    row(
        &mut out,
        "troupe foxglove, 1 client (all)",
        &f,
        Some((
            got.channels.load(Ordering::Relaxed),
            (m1 - m0) as f64 / f.wall,
            (b1 - b0) as f64 / 1e6 / f.wall,
        )),
    )?;
    writeln!(
        out,
        "  (target: the fleet's rates unchanged, the server at most 15% of a core with one client)"
    )?;
    drop(server);
    drop(launcher);
    Ok(())
}
