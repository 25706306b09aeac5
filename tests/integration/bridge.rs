//! Player transcripts (../shared/compat/player-tcp) replayed against
//! `troupe launch` of the same cfg: every client message is sent as the real
//! client sent it, and the bridge's answers must match the real Player
//! server's byte for byte — header timestamps, simulation-dependent values,
//! uninitialised memory of the original and the number of DATA messages per
//! round aside (the transcripts' README lists these).

use std::collections::{HashMap, HashSet};
use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::time::Instant;

use troupe_tests::{Proc, DEADLINE};

use crate::player::{Frame, DATA, RESP_ACK, SYNCH};

/// One recorded message: its place in the transcript, its direction, what
/// it says, and the transcript's note for messages.
#[derive(Debug, Clone)]
struct Msg {
    n: usize,
    s2c: bool,
    frame: Frame,
    note: String,
}

impl std::ops::Deref for Msg {
    type Target = Frame;
    fn deref(&self) -> &Frame {
        &self.frame
    }
}

fn hex(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
        .collect()
}

/// The banner and the messages of a transcript.
fn load(dir: &Path) -> (Vec<u8>, Vec<Msg>) {
    let text = std::fs::read_to_string(dir.join("messages.jsonl")).unwrap();
    let mut banner = Vec::new();
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let v: serde_json::Value = serde_json::from_str(line).unwrap();
        let body = hex(v["body_hex"].as_str().unwrap_or(""));
        if v["banner"].as_bool() == Some(true) {
            banner = body;
            continue;
        }
        let f = |k: &str| u32::try_from(v[k].as_u64().unwrap()).unwrap();
        out.push(Msg {
            n,
            s2c: v["dir"] == "s2c",
            frame: Frame {
                h: [
                    f("host"),
                    f("robot"),
                    f("interf"),
                    f("index"),
                    f("type"),
                    f("subtype"),
                ],
                // The client's timestamp, resent as recorded.
                timestamp: v["timestamp"].as_f64().unwrap(),
                seq: f("seq"),
                body,
            },
            note: v["note"].as_str().unwrap_or("").to_owned(),
        });
    }
    (banner, out)
}

/// Byte ranges of a reply body that hold uninitialised memory in the
/// original server or values that depend on the simulation's run.
fn masked(sig: (u32, u32, u32, u32)) -> &'static [(usize, usize)] {
    match sig {
        // position2d GET_GEOM: pose.pz, proll, ppitch and size.sh.
        (4, _, RESP_ACK, 1) => &[(16, 40), (64, 72)],
        // fiducial GET_GEOM: size.sh and fiducial_size.
        (10, _, RESP_ACK, 1) => &[(64, 88)],
        _ => &[],
    }
}

fn same_reply(got: &Frame, want: &Msg) -> Result<(), String> {
    let header_ok = if want.kind() == SYNCH {
        (got.h[2], got.h[4], got.h[5]) == (want.h[2], want.h[4], want.h[5])
    } else {
        got.h == want.h && got.seq == want.seq
    };
    if !header_ok || got.body.len() != want.body.len() {
        return Err(format!(
            "header {:?} size {} (want {:?} size {})",
            got.h,
            got.body.len(),
            want.h,
            want.body.len()
        ));
    }
    let mask = masked(want.sig());
    let diff: Vec<usize> = (0..got.body.len())
        .filter(|i| !mask.iter().any(|&(a, b)| (a..b).contains(i)))
        .filter(|&i| got.body[i] != want.body[i])
        .collect();
    if diff.is_empty() {
        Ok(())
    } else {
        Err(format!(
            "bodies differ at bytes {diff:?}\n   got {}\n  want {}",
            hexs(&got.body),
            hexs(&want.body)
        ))
    }
}

fn hexs(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

/// The stack of a scenario, with the bridge on free ports.
struct Stack {
    launcher: Proc,
    ports: HashMap<u32, String>,
}

fn launch(cfg: &Path, robots: &[u32]) -> Stack {
    let ns = troupe_tests::unique_namespace("bridge");
    let mut launcher = troupe_tests::launch(&ns, cfg, &[]);
    let lines = launcher.lines();
    let mut ports = HashMap::new();
    let deadline = Instant::now() + DEADLINE;
    while ports.len() < robots.len() {
        let left = deadline.saturating_duration_since(Instant::now());
        let line = lines
            .recv_timeout(left)
            .unwrap_or_else(|_| panic!("no bridge ports printed by `troupe launch {cfg:?}`"));
        if let Some(rest) = line.strip_prefix("troupe bridge: robot ") {
            let (robot, addr) = rest.split_once(" on ").unwrap();
            ports.insert(robot.parse().unwrap(), addr.to_owned());
        }
    }
    Stack { launcher, ports }
}

/// Replays the client side of a transcript and checks the server side.
fn replay(addr: &str, banner: &[u8], msgs: &[Msg]) {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(DEADLINE)).unwrap();
    let mut b = [0u8; 32];
    s.read_exact(&mut b).unwrap();
    assert_eq!(&b[..], banner, "banner");
    // The DATA kinds (and their sizes) the real server sent.
    let mut kinds: HashMap<(u32, u32, u32, u32), HashSet<usize>> = HashMap::new();
    for m in msgs.iter().filter(|m| m.s2c && m.kind() == DATA) {
        kinds.entry(m.sig()).or_default().insert(m.body.len());
    }
    let variable = |interf: u32| matches!(interf, 7 | 10); // blobs, fiducials: as seen
    let mut data_since_reply = 0usize;
    let mut replies = 0usize;
    let mut i = 0;
    while i < msgs.len() {
        let m = &msgs[i];
        i += 1;
        if m.s2c {
            continue;
        }
        s.write_all(&m.encode()).unwrap();
        let expected: Vec<&Msg> = msgs[i..]
            .iter()
            .take_while(|x| x.s2c)
            .filter(|x| x.kind() != DATA)
            .collect();
        for want in expected {
            let got = loop {
                let got = Frame::read(&mut s);
                if got.kind() != DATA {
                    break got;
                }
                let sizes = kinds
                    .get(&got.sig())
                    .unwrap_or_else(|| panic!("unexpected DATA {:?} before #{}", got.h, want.n));
                assert!(
                    variable(got.h[2]) || sizes.contains(&got.body.len()),
                    "DATA {:?} of {} bytes; the original sent {sizes:?}",
                    got.h,
                    got.body.len()
                );
                data_since_reply += 1;
            };
            if want.kind() == SYNCH {
                assert!(
                    data_since_reply > 0,
                    "SYNCH #{} with no DATA in its round",
                    want.n
                );
            }
            if let Err(e) = same_reply(&got, want) {
                panic!("#{} {}: {e}", want.n, want.note);
            }
            data_since_reply = 0;
            replies += 1;
        }
    }
    assert!(replies > 0);
}

fn scenario(dir: &str, cfg: &str) {
    let Some(d) = troupe_tests::compat(&format!("player-tcp/{dir}")) else {
        return;
    };
    let (banner, msgs) = load(&d);
    let mut stack = launch(&d.join(cfg), &[6665]);
    replay(&stack.ports[&6665], &banner, &msgs);
    assert!(
        stack.launcher.terminate().success(),
        "{}",
        stack.launcher.stderr()
    );
}

#[test]
fn c_pull_position_laser() {
    scenario("c-pull-position-laser", "simple_noctrl_headless.cfg");
}

#[test]
fn cpp_position_ranger_geom() {
    scenario("cpp-position-ranger-geom", "simple_noctrl_headless.cfg");
}

#[test]
fn c_push_mode() {
    scenario("c-push-mode", "simple_noctrl_headless.cfg");
}

#[test]
fn cpp_simulation() {
    scenario("cpp-simulation", "simple_noctrl_headless.cfg");
}

#[test]
fn py_playerc() {
    scenario("py-playerc", "simple_noctrl_headless.cfg");
}

#[test]
fn cpp_blob_fiducial_gripper() {
    scenario(
        "cpp-blob-fiducial-gripper",
        "everything_robot1_headless.cfg",
    );
}

#[test]
fn c_errors_on_two_ports() {
    let Some(d) = troupe_tests::compat("player-tcp/c-errors") else {
        return;
    };
    let (banner, msgs) = load(&d);
    let (_, msgs2) = load(&d.join("conn2-6667"));
    let mut stack = launch(&d.join("errors_two_ports.cfg"), &[6665, 6667]);
    replay(&stack.ports[&6665], &banner, &msgs);
    replay(&stack.ports[&6667], &banner, &msgs2);
    assert!(
        stack.launcher.terminate().success(),
        "{}",
        stack.launcher.stderr()
    );
}
