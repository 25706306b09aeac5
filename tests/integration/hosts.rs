//! Two hosts on this machine: network namespaces joined by a veth pair, a
//! `troupe router` in each, one plan split between them with `--host`.
//! Needs root and `ip netns` (iproute2, installed by .ci/run); skips otherwise.

use std::process::Command;
use std::sync::mpsc::Receiver;
use std::time::{Duration, Instant};

use troupe_tests::{strings, Proc};

/// Link loss is noticed through Zenoh's lease (10 s by default).
const LINK_DEADLINE: Duration = Duration::from_secs(60);

const A: &str = "10.201.0.1";
const B: &str = "10.201.0.2";

fn ip(args: &[&str]) -> bool {
    Command::new("ip")
        .args(args)
        .status()
        .is_ok_and(|s| s.success())
}

/// Two namespaces joined by a veth pair; deleted on drop.
struct Hosts {
    a: String,
    b: String,
}

impl Hosts {
    fn new() -> Option<Hosts> {
        let id = std::process::id();
        let h = Hosts {
            a: format!("troupe-{id}-a"),
            b: format!("troupe-{id}-b"),
        };
        let (va, vb) = (format!("tra{id}"), format!("trb{id}"));
        let (va, vb) = (&va[..va.len().min(15)], &vb[..vb.len().min(15)]);
        let ok = ip(&["netns", "add", &h.a])
            && ip(&["netns", "add", &h.b])
            && ip(&["link", "add", va, "type", "veth", "peer", "name", vb])
            && ip(&["link", "set", va, "netns", &h.a])
            && ip(&["link", "set", vb, "netns", &h.b])
            && ip(&["-n", &h.a, "addr", "add", &format!("{A}/30"), "dev", va])
            && ip(&["-n", &h.b, "addr", "add", &format!("{B}/30"), "dev", vb])
            && ip(&["-n", &h.a, "link", "set", va, "up"])
            && ip(&["-n", &h.b, "link", "set", vb, "up"])
            && ip(&["-n", &h.a, "link", "set", "lo", "up"])
            && ip(&["-n", &h.b, "link", "set", "lo", "up"]);
        ok.then_some(h)
    }

    fn link(&self, up: bool) {
        let id = std::process::id();
        let va = format!("tra{id}");
        let va = &va[..va.len().min(15)];
        assert!(ip(&[
            "-n",
            &self.a,
            "link",
            "set",
            va,
            if up { "up" } else { "down" }
        ]));
    }
}

impl Drop for Hosts {
    fn drop(&mut self) {
        ip(&["netns", "del", &self.a]);
        ip(&["netns", "del", &self.b]);
    }
}

/// Waits for a line containing all of `words`.
fn expect_line(rx: &Receiver<String>, words: &[&str], deadline: Duration) -> String {
    wait_line(rx, words, deadline)
        .unwrap_or_else(|| panic!("no line with {words:?} within {deadline:?}"))
}

/// A line containing all of `words`, if one comes within `deadline`.
fn wait_line(rx: &Receiver<String>, words: &[&str], deadline: Duration) -> Option<String> {
    let end = Instant::now() + deadline;
    loop {
        let left = end.saturating_duration_since(Instant::now());
        match rx.recv_timeout(left) {
            Ok(l) if words.iter().all(|w| l.contains(w)) => return Some(l),
            Ok(_) => {}
            Err(_) => return None,
        }
    }
}

const PLAN: &str = r#"
[[node]]
name = "ranger"
driver = "dummy"
host = "a"
provides = [{ device = "robot/6665/ranger/0" }]
[node.options]
rate = 20

[[node]]
name = "laser"
driver = "rangertolaser"
host = "b"
requires = [{ device = "robot/6665/ranger/0" }]
provides = [{ device = "robot/6665/laser/0" }]
"#;

#[test]
fn a_plan_split_across_two_hosts_runs_and_heals_after_a_cut_link() {
    let Some(hosts) = Hosts::new() else {
        troupe_tests::cannot_run("it needs root and `ip netns` to make two hosts");
        return;
    };
    let dir = std::env::temp_dir().join(troupe_tests::unique_namespace("hosts"));
    std::fs::create_dir_all(&dir).unwrap();
    let plan = dir.join("fleet.toml");
    std::fs::write(&plan, PLAN).unwrap();
    let plan = plan.to_str().unwrap();
    // Each router listens on an ephemeral port of its host; its banner says which.
    let endpoint = |p: &mut Proc| {
        let line = p.first_line();
        line.trim()
            .rsplit(' ')
            .next()
            .unwrap_or_default()
            .to_owned()
    };
    let mut ra = Proc::troupe_in(
        &hosts.a,
        "router a",
        &strings(&[
            "router",
            "--listen",
            &format!("tcp/{A}:0"),
            "--no-multicast",
        ]),
    );
    let ea = endpoint(&mut ra);
    let mut rb = Proc::troupe_in(
        &hosts.b,
        "router b",
        &strings(&[
            "router",
            "--listen",
            &format!("tcp/{B}:0"),
            "--connect",
            &ea,
            "--no-multicast",
        ]),
    );
    let eb = endpoint(&mut rb);
    assert!(
        ea.starts_with(&format!("tcp/{A}:")) && eb.starts_with(&format!("tcp/{B}:")),
        "{ea} {eb}"
    );
    let at = |e: &str| strings(&["--connect", e, "--no-multicast"]);
    let with = |mut v: Vec<String>, more: &[&str]| {
        v.extend(strings(more));
        v
    };

    let mut watch = Proc::troupe_in(&hosts.a, "watch", &with(at(&ea), &["list", "--watch"]));
    let events = watch.lines();
    let mut la = Proc::troupe_in(
        &hosts.a,
        "launch a",
        &with(
            at(&ea),
            &["launch", plan, "--host", "a", "--bridge-any-port"],
        ),
    );
    let mut lb = Proc::troupe_in(
        &hosts.b,
        "launch b",
        &with(
            at(&eb),
            &["launch", plan, "--host", "b", "--bridge-any-port"],
        ),
    );

    // Host B's node needs host A's device: both come up, seen from A.
    for words in [
        ["+", "ranger:0", "dummy"],
        ["+", "laser:0", "rangertolaser"],
    ] {
        if wait_line(&events, &words, LINK_DEADLINE).is_none() {
            // What each host said, for the one who reads the failure.
            panic!(
                "no line with {words:?} within {LINK_DEADLINE:?}\n--- launch a ---\n{}\n--- launch b ---\n{}\n--- router b ---\n{}",
                la.stderr(),
                lb.stderr(),
                rb.stderr()
            );
        }
    }

    // The whole fleet from either host; data from B reaches a client on A.
    for (ns, e) in [(&hosts.a, &ea), (&hosts.b, &eb)] {
        let mut l = Proc::troupe_in(ns, "list", &with(at(e), &["list"]));
        let out: Vec<String> = l.lines().iter().collect();
        assert!(l.wait().success());
        assert!(
            out.iter().any(|x| x.contains("ranger:0")) && out.iter().any(|x| x.contains("laser:0")),
            "{ns}: {out:?}"
        );
    }
    let mut echo = Proc::troupe_in(
        &hosts.a,
        "echo",
        &with(at(&ea), &["echo", "laser:0", "--count", "1", "--json"]),
    );
    let sample = expect_line(&echo.lines(), &["LaserScan"], LINK_DEADLINE);
    assert!(echo.wait().success());
    let v: serde_json::Value = serde_json::from_str(&sample).unwrap();
    assert_eq!(v["msg"]["ranges"].as_array().unwrap().len(), 361);

    // Cut the link: B's device drops out of A's view; restore it: it comes back.
    hosts.link(false);
    expect_line(&events, &["-", "laser:0"], LINK_DEADLINE);
    hosts.link(true);
    expect_line(&events, &["+", "laser:0"], LINK_DEADLINE);

    assert!(lb.terminate().success(), "launch b: {}", lb.stderr());
    assert!(la.terminate().success(), "launch a: {}", la.stderr());
}
