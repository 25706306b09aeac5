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

/// `n` hosts on this machine, each a network namespace with a veth to a
/// bridge in a core namespace (the fleet's network, 10.202.0.0/24: the
/// core at .254, host i at .i+1); deleted on drop.
struct Star {
    core: String,
    hosts: Vec<String>,
    /// Each host's end of its link, in its namespace.
    links: Vec<String>,
}

const CORE: &str = "10.202.0.254";

impl Star {
    fn new(n: usize) -> Option<Star> {
        let id = std::process::id() % 100_000;
        let mut s = Star {
            core: format!("troupe-{id}-core"),
            hosts: Vec::new(),
            links: Vec::new(),
        };
        let core = s.core.clone();
        let mut ok = ip(&["netns", "add", &core])
            && ip(&["-n", &core, "link", "set", "lo", "up"])
            && ip(&["-n", &core, "link", "add", "br0", "type", "bridge"])
            && ip(&[
                "-n",
                &core,
                "addr",
                "add",
                &format!("{CORE}/24"),
                "dev",
                "br0",
            ])
            && ip(&["-n", &core, "link", "set", "br0", "up"]);
        for i in 0..n {
            if !ok {
                break;
            }
            let ns = format!("troupe-{id}-h{i}");
            let (hv, cv) = (format!("t{id}h{i}"), format!("t{id}c{i}"));
            ok = ip(&["netns", "add", &ns])
                && ip(&["link", "add", &hv, "type", "veth", "peer", "name", &cv])
                && ip(&["link", "set", &hv, "netns", &ns])
                && ip(&["link", "set", &cv, "netns", &core])
                && ip(&["-n", &core, "link", "set", &cv, "master", "br0"])
                && ip(&["-n", &core, "link", "set", &cv, "up"])
                && ip(&[
                    "-n",
                    &ns,
                    "addr",
                    "add",
                    &format!("10.202.0.{}/24", i + 1),
                    "dev",
                    &hv,
                ])
                && ip(&["-n", &ns, "link", "set", &hv, "up"])
                && ip(&["-n", &ns, "link", "set", "lo", "up"]);
            s.hosts.push(ns);
            s.links.push(hv);
        }
        ok.then_some(s)
    }

    /// Bytes received and sent on host `i`'s link: what its router
    /// exchanged with the fleet (its nodes reach it on the same address,
    /// through the loopback).
    fn bytes(&self, i: usize) -> (u64, u64) {
        let read = |what: &str| -> u64 {
            let out = Command::new("ip")
                .args(["netns", "exec", &self.hosts[i], "cat"])
                .arg(format!(
                    "/sys/class/net/{}/statistics/{what}_bytes",
                    self.links[i]
                ))
                .output()
                .expect("cat");
            String::from_utf8_lossy(&out.stdout)
                .trim()
                .parse()
                .unwrap_or(0)
        };
        (read("rx"), read("tx"))
    }
}

impl Drop for Star {
    fn drop(&mut self) {
        for h in &self.hosts {
            ip(&["netns", "del", h]);
        }
        ip(&["netns", "del", &self.core]);
    }
}

/// A fleet of 20 hosts, each a namespace with a Zenoh router of its own
/// (linked to the fleet's router in the core) and a robot's drivers
/// (a ranger, and rangertolaser reading it, one process each): every
/// robot's devices come up, a robot's scan reaches a client on another
/// host, and what crossed each host's link is printed beside what its
/// robot published (its ranger and laser, which no one elsewhere reads),
/// with the CPU each router spent from its start.
#[test]
fn twenty_hosts_each_with_its_router_come_up_and_a_robot_s_scan_reaches_another() {
    const N: usize = 20;
    let Some(star) = Star::new(N) else {
        troupe_tests::cannot_run("it needs root and `ip netns` to make twenty hosts");
        return;
    };
    let dir = std::env::temp_dir().join(troupe_tests::unique_namespace("star"));
    std::fs::create_dir_all(&dir).unwrap();
    let mut plan = String::new();
    for i in 0..N {
        let port = 6665 + i;
        plan.push_str(&format!(
            "[[node]]\nname = \"ranger-{i}\"\ndriver = \"dummy\"\nhost = \"h{i}\"\n\
             provides = [{{ device = \"robot/{port}/ranger/0\" }}]\n[node.options]\nrate = 10\n\n\
             [[node]]\nname = \"laser-{i}\"\ndriver = \"rangertolaser\"\nhost = \"h{i}\"\n\
             requires = [{{ device = \"robot/{port}/ranger/0\" }}]\n\
             provides = [{{ device = \"robot/{port}/laser/0\" }}]\n\n"
        ));
    }
    let plan_path = dir.join("star.toml");
    std::fs::write(&plan_path, plan).unwrap();
    let plan = plan_path.to_str().unwrap();
    let listen = |p: &mut Proc| p.endpoint("troupe router listening on");
    let mut core = Proc::troupe_in(
        &star.core,
        "core router",
        &strings(&[
            "router",
            "--listen",
            &format!("tcp/{CORE}:0"),
            "--no-multicast",
        ]),
    );
    let ec = listen(&mut core);
    let at = |e: &str, more: &[&str]| {
        let mut v = strings(&["--connect", e, "--no-multicast"]);
        v.extend(strings(more));
        v
    };
    let mut watch = Proc::troupe_in(&star.core, "watch", &at(&ec, &["list", "--watch"]));
    let events = watch.lines();

    let t = Instant::now();
    let mut procs = Vec::new();
    let mut endpoints = Vec::new();
    for (i, ns) in star.hosts.iter().enumerate() {
        let mut r = Proc::troupe_in(
            ns,
            &format!("router h{i}"),
            &strings(&[
                "router",
                "--listen",
                &format!("tcp/10.202.0.{}:0", i + 1),
                "--connect",
                &ec,
                "--no-multicast",
            ]),
        );
        let e = listen(&mut r);
        let l = Proc::troupe_in(
            ns,
            &format!("launch h{i}"),
            &at(
                &e,
                &["launch", plan, "--host", &format!("h{i}"), "--no-bridge"],
            ),
        );
        procs.push(r);
        procs.push(l);
        endpoints.push(e);
    }
    let started = t.elapsed();
    // Every robot's ranger and laser, seen from the core.
    let mut want: std::collections::BTreeSet<String> = (0..N)
        .flat_map(|i| {
            let port = 6665 + i;
            [
                format!("robot/{port} ranger:0"),
                format!("robot/{port} laser:0"),
            ]
        })
        .collect();
    let deadline = Instant::now() + LINK_DEADLINE * 2;
    while !want.is_empty() {
        let left = deadline.saturating_duration_since(Instant::now());
        let Ok(line) = events.recv_timeout(left) else {
            panic!("not live within {:?}: {want:?}", LINK_DEADLINE * 2);
        };
        let words: Vec<&str> = line.split_whitespace().collect();
        if words.first() == Some(&"+") {
            if let (Some(r), Some(d)) = (
                words.iter().find(|w| w.starts_with("robot/")),
                words.iter().find(|w| w.ends_with(":0")),
            ) {
                want.remove(&format!("{r} {d}"));
            }
        }
    }
    let ready = t.elapsed();

    // The last robot's scan, read on the first host.
    let last = 6665 + N - 1;
    let mut echo = Proc::troupe_in(
        &star.hosts[0],
        "echo",
        &at(
            &endpoints[0],
            &[
                "echo",
                &format!("robot/{last}/laser/0"),
                "--count",
                "1",
                "--json",
            ],
        ),
    );
    let sample = expect_line(&echo.lines(), &["LaserScan"], LINK_DEADLINE);
    assert!(echo.wait().success());
    let v: serde_json::Value = serde_json::from_str(&sample).unwrap();
    assert!(
        !v["msg"]["ranges"].as_array().unwrap().is_empty(),
        "{sample}"
    );

    // What each host's router exchanged with the fleet, from its start.
    let secs = t.elapsed().as_secs_f64();
    let mut rates: Vec<f64> = (0..N)
        .map(|i| {
            let (rx, tx) = star.bytes(i);
            (rx + tx) as f64 / secs / 1e3
        })
        .collect();
    rates.sort_by(f64::total_cmp);
    // What each router spent, as a share of one core over the run.
    let mut cpu: Vec<f64> = procs
        .iter()
        .step_by(2)
        .map(|r| 100.0 * r.cpu_seconds() / secs)
        .collect();
    cpu.sort_by(f64::total_cmp);
    eprintln!(
        "20 hosts: routers and launches started in {:.2} s; all {} devices live {:.1} s after the first start; \
         each host's link carried {:.1}–{:.1} kB/s (median {:.1}) over {secs:.1} s; robot {last}'s scan reached a client on host h0; \
         CPU of a core: each host's router {:.1}–{:.1}% (median {:.1}), the fleet's router {:.1}%",
        started.as_secs_f64(),
        2 * N,
        ready.as_secs_f64(),
        rates[0],
        rates[N - 1],
        rates[N / 2],
        cpu[0],
        cpu[N - 1],
        cpu[N / 2],
        100.0 * core.cpu_seconds() / secs,
    );
    // All told to stop at once: each launcher stops its nodes in turn.
    let t = Instant::now();
    for p in procs.iter().rev() {
        p.term();
    }
    for mut p in procs.into_iter().rev() {
        assert!(p.wait().success(), "{}", p.stderr());
    }
    eprintln!(
        "20 hosts: every process stopped {:.1} s after SIGTERM",
        t.elapsed().as_secs_f64()
    );
    let _ = std::fs::remove_dir_all(&dir);
}
