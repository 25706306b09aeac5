//! `troupe launch` as a user runs it: a cfg becomes processes; killed nodes
//! come back; SIGTERM stops everything; a killed launcher leaves no orphan.

use std::path::PathBuf;
use std::time::Instant;

use troupe_node::zenoh::sample::SampleKind;
use troupe_tests::{client_at, strings, token_events, troupe_output, Proc, DEADLINE};

const STACK: &str = "driver ( name \"dummy\" provides [\"ranger:0\"] rate 20 )\n\
                     driver ( name \"rangertolaser\" requires [\"ranger:0\"] provides [\"laser:0\"] )\n";

fn temp_cfg(name: &str, text: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(troupe_tests::unique_namespace(name));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("robot.cfg");
    std::fs::write(&p, text).unwrap();
    p
}

/// Starts `troupe launch` on an ephemeral port; returns it, its endpoint and namespace.
fn launch(cfg: &std::path::Path, extra: &[&str]) -> (Proc, String, String) {
    let ns = troupe_tests::unique_namespace("launch");
    let mut p = troupe_tests::launch(&ns, cfg, extra);
    let endpoint = p.endpoint("troupe launch: router listening on");
    (p, endpoint, ns)
}

/// Process `pid`'s command line, its arguments joined by spaces.
fn cmdline(pid: u32) -> String {
    std::fs::read_to_string(format!("/proc/{pid}/cmdline"))
        .unwrap_or_default()
        .replace('\0', " ")
}

/// Children of `parent` whose command line mentions `word`.
fn children(parent: u32, word: &str) -> Vec<u32> {
    let mut out = Vec::new();
    for e in std::fs::read_dir("/proc").unwrap().flatten() {
        let Ok(pid) = e.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let Ok(stat) = std::fs::read_to_string(format!("/proc/{pid}/stat")) else {
            continue;
        };
        // The fields after the parenthesised command: state, ppid, …
        let Some(rest) = stat.rsplit_once(") ").map(|(_, r)| r) else {
            continue;
        };
        let mut f = rest.split(' ');
        let (state, ppid) = (f.next(), f.next().and_then(|p| p.parse::<u32>().ok()));
        if ppid == Some(parent) && state != Some("Z") && cmdline(pid).contains(word) {
            out.push(pid);
        }
    }
    out
}

/// Waits until the tokens of `n` distinct devices have come on `tokens`
/// (from [`token_events`]), by `deadline`.
fn until_up(
    tokens: &troupe_node::zenoh::pubsub::Subscriber<
        troupe_node::zenoh::handlers::FifoChannelHandler<troupe_node::zenoh::sample::Sample>,
    >,
    n: usize,
    deadline: Instant,
) {
    let mut up = std::collections::BTreeSet::new();
    while up.len() < n {
        let t = tokens
            .recv_deadline(deadline)
            .unwrap()
            .unwrap_or_else(|| panic!("{n} devices up (only {up:?})"));
        up.insert(t.key_expr().to_string());
    }
}

/// True once `pid` is gone (or a zombie), within the deadline.
fn gone(pid: u32) -> bool {
    let deadline = Instant::now() + DEADLINE;
    while Instant::now() < deadline {
        match std::fs::read_to_string(format!("/proc/{pid}/stat")) {
            Err(_) => return true,
            Ok(s) if s.rsplit_once(") ").is_some_and(|(_, r)| r.starts_with('Z')) => return true,
            Ok(_) => std::thread::yield_now(),
        }
    }
    false
}

#[test]
fn launch_runs_the_stack_restarts_a_killed_node_and_stops_cleanly() {
    let cfg = temp_cfg("stack", STACK);
    let logs = cfg.with_file_name("logs");
    let (mut launcher, endpoint, ns) = launch(&cfg, &["--log-dir", logs.to_str().unwrap()]);
    let s = client_at(&endpoint, &ns);
    let tokens = token_events(&s);
    let deadline = Instant::now() + DEADLINE;
    until_up(&tokens, 2, deadline);

    let net = strings(&["--connect", &endpoint, "--namespace", &ns, "--no-multicast"]);
    let mut list = net.clone();
    list.push("list".into());
    let (st, out, err) = troupe_output(&list);
    assert!(st.success(), "{err}");
    assert!(out.contains("laser:0") && out.contains("ranger:0"), "{out}");

    // Kill the converter: its device drops out, then comes back.
    let pid = launcher.child.id();
    let victims = children(pid, "rangertolaser");
    assert_eq!(victims.len(), 1, "one rangertolaser child");
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(victims[0] as i32),
        nix::sys::signal::Signal::SIGKILL,
    )
    .unwrap();
    let laser = "robot/6665/laser/0/driver/rangertolaser";
    let mut dropped = false;
    loop {
        let t = tokens
            .recv_deadline(deadline)
            .unwrap()
            .expect("the laser comes back");
        if t.key_expr().as_str() == laser {
            match t.kind() {
                SampleKind::Delete => dropped = true,
                SampleKind::Put if dropped => break,
                SampleKind::Put => {}
            }
        }
    }
    let again = children(pid, "rangertolaser");
    assert_eq!(again.len(), 1);
    assert_ne!(again[0], victims[0], "a new process serves the laser");
    let all = children(pid, "troupe");

    assert!(launcher.terminate().success(), "{}", launcher.stderr());
    for c in all {
        assert!(gone(c), "child {c} outlived the launcher");
    }
    // One log file per node, across restarts.
    let log = std::fs::read_to_string(logs.join("rangertolaser.log")).unwrap();
    assert_eq!(
        log.matches("ready: provides 6665:laser:0").count(),
        2,
        "{log}"
    );
    assert!(std::fs::read_to_string(logs.join("dummy.log"))
        .unwrap()
        .contains("ready"));
}

#[test]
fn a_section_too_long_for_an_argument_reaches_its_node_on_stdin() {
    // Linux takes at most 128 KiB in one argument; a world of thousands of
    // robots makes a stage section longer than that.
    let long = "x".repeat(150_000);
    let cfg = temp_cfg(
        "long-section",
        &format!("driver ( name \"dummy\" provides [\"ranger:0\"] rate 20 note \"{long}\" )\n"),
    );
    let (launcher, endpoint, ns) = launch(&cfg, &["--no-bridge"]);
    let s = client_at(&endpoint, &ns);
    let tokens = token_events(&s);
    until_up(&tokens, 1, Instant::now() + DEADLINE);
    let nodes = children(launcher.child.id(), "dummy");
    assert_eq!(nodes.len(), 1, "one dummy child");
    let cmd = cmdline(nodes[0]);
    assert!(
        cmd.contains("node dummy --section - "),
        "{}",
        &cmd[..cmd.len().min(300)]
    );
}

#[test]
fn a_killed_launcher_takes_its_nodes_with_it() {
    let cfg = temp_cfg("orphans", STACK);
    // The bridge starts once the devices are up: leave it out so the count is exact.
    let (mut launcher, endpoint, ns) = launch(&cfg, &["--no-bridge"]);
    let s = client_at(&endpoint, &ns);
    let tokens = token_events(&s);
    let deadline = Instant::now() + DEADLINE;
    for _ in 0..2 {
        tokens
            .recv_deadline(deadline)
            .unwrap()
            .expect("devices come up");
    }
    let kids = children(launcher.child.id(), "troupe");
    assert_eq!(kids.len(), 2, "{kids:?}");
    launcher.child.kill().unwrap();
    launcher.wait();
    for k in kids {
        assert!(gone(k), "node {k} survived its launcher");
    }
}

#[test]
fn plan_and_dry_run_print_the_plan_and_bad_cfgs_say_where() {
    let cfg = temp_cfg("plan", STACK);
    let (st, out, err) = troupe_output(&strings(&["plan", cfg.to_str().unwrap(), "-p", "7000"]));
    assert!(st.success(), "{err}");
    assert!(
        out.contains("device = \"robot/7000/laser/0\"") && out.contains("start_order = 2"),
        "{out}"
    );
    let plan = cfg.with_file_name("plan.toml");
    std::fs::write(&plan, &out).unwrap();
    let (st, again, err) =
        troupe_output(&strings(&["launch", plan.to_str().unwrap(), "--dry-run"]));
    assert!(st.success(), "{err}");
    assert!(again.contains("robot/7000/ranger/0"), "{again}");

    let bad = temp_cfg(
        "bad",
        "driver\n(\n  name \"dummy\"\n  provides [\"laser:0\"\n)\n",
    );
    let (st, _, err) = troupe_output(&strings(&["launch", bad.to_str().unwrap()]));
    assert!(!st.success());
    assert!(err.contains("robot.cfg:5:1: expected `]`"), "{err}");
    let missing = temp_cfg(
        "missing",
        "driver ( name \"rangertolaser\" requires [\"ranger:0\"] provides [\"laser:0\"] )\n",
    );
    let (st, _, err) = troupe_output(&strings(&["launch", missing.to_str().unwrap()]));
    assert!(!st.success());
    assert!(
        err.contains("requires 6665:ranger:0, which nothing provides"),
        "{err}"
    );
}

/// A duration flag given `inf` is refused by clap (exit 2, a message), not
/// a backtrace where it becomes a `Duration`.
#[test]
fn infinite_and_negative_durations_are_refused_with_a_message() {
    let cfg = temp_cfg("durations", STACK);
    let cfg = cfg.to_str().unwrap();
    for (flag, value, says) in [
        ("--ready-timeout", "inf", "inf is not a finite number"),
        ("--grace", "inf", "inf is not a finite number"),
        ("--grace", "NaN", "NaN is not a finite number"),
        ("--ready-timeout", "-1", "-1 is negative"),
    ] {
        let (st, _, err) = troupe_output(&strings(&["launch", cfg, &format!("{flag}={value}")]));
        assert_eq!(st.code(), Some(2), "{flag} {value}: {err}");
        assert!(
            err.contains(says) && !err.contains("panicked"),
            "{flag} {value}: {err}"
        );
    }
}

/// Drives robot 7000's base (a passthrough's) 10 cm, from its odometry.
fn drives_through_7000(robot: &troupe_client::Client) {
    let pp = troupe_client::Position2dProxy::new(robot, 0).unwrap();
    let deadline = Instant::now() + DEADLINE;
    while pp.data().is_none() {
        assert!(
            Instant::now() < deadline,
            "no odometry through 7000:position2d:0"
        );
        robot.read().unwrap();
    }
    let (x0, y0) = (pp.x(), pp.y());
    pp.set_speed(0.3, 0.0).unwrap();
    let deadline = Instant::now() + DEADLINE;
    while (pp.x() - x0).hypot(pp.y() - y0) < 0.1 {
        assert!(Instant::now() < deadline, "r0 never moved");
        robot.read().unwrap();
    }
    pp.set_speed(0.0, 0.0).unwrap();
}

/// Kills `parent`'s child that runs `word`, and sees on `tokens` (which saw
/// the device live first: their history) the device under key `prefix`
/// go away and come back with it.
fn kill_and_see_it_return(
    parent: u32,
    word: &str,
    tokens: &troupe_node::zenoh::pubsub::Subscriber<
        troupe_node::zenoh::handlers::FifoChannelHandler<troupe_node::zenoh::sample::Sample>,
    >,
    prefix: &str,
) {
    let victims = children(parent, word);
    assert_eq!(victims.len(), 1);
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(victims[0] as i32),
        nix::sys::signal::Signal::SIGKILL,
    )
    .unwrap();
    let mut left = false;
    let deadline = Instant::now() + DEADLINE;
    loop {
        let s = tokens
            .recv_deadline(deadline)
            .unwrap()
            .unwrap_or_else(|| panic!("{prefix} did not go away and come back (gone: {left})"));
        if !s.key_expr().as_str().starts_with(prefix) {
            continue;
        }
        match s.kind() {
            SampleKind::Delete => left = true,
            SampleKind::Put if left => break,
            SampleKind::Put => {}
        }
    }
}

/// Player 3's local passthrough (issue 30, item 1): robot 6665's laser and
/// base served again as robot 7000's. Scans and geometry come through, a
/// velocity command moves 6665's base, and when the laser's driver dies
/// 7000's laser leaves and comes back with it.
#[test]
fn a_local_passthrough_relays_and_follows_its_device() {
    use troupe_client::{Client, LaserProxy};
    let world = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds/simple.world");
    let base = format!(
        "driver ( name \"stage\" provides [\"simulation:0\"] worldfile \"{}\" )\n\
         driver ( name \"stage\" provides [\"position2d:0\"] model \"r0\" )\n",
        world.canonicalize().unwrap().display()
    );
    let cfg = temp_cfg(
        "passthrough",
        &format!(
            "{STACK}{base}driver ( name \"passthrough\" requires [\"laser:0\" \"position2d:0\"] provides [\"7000:laser:0\" \"7000:position2d:0\"] )\n"
        ),
    );
    let (mut launcher, endpoint, ns) = launch(&cfg, &["--no-bridge"]);
    let session = client_at(&endpoint, &ns);
    troupe_tests::wait_live(&session, &["7000:laser:0", "7000:position2d:0"]);
    let tokens = token_events(&session);
    let robot = Client::with_session(session.clone(), 7000);
    let lp = LaserProxy::new(&robot, 0).unwrap();
    let deadline = Instant::now() + DEADLINE;
    while lp.count() == 0 {
        assert!(Instant::now() < deadline, "no scans through 7000:laser:0");
        robot.read().unwrap();
    }
    // A request goes to rangertolaser, which asks the dummy ranger; the
    // dummy's refusal comes back all the way.
    let e = lp.request_geom().unwrap_err().to_string();
    assert!(e.contains("the dummy driver refuses every request"), "{e}");
    // A command through 7000 drives r0, robot 6665's base.
    drives_through_7000(&robot);

    // rangertolaser dies: 7000:laser:0 leaves, then comes back with it.
    kill_and_see_it_return(
        launcher.child.id(),
        "rangertolaser",
        &tokens,
        "robot/7000/laser/0/",
    );
    assert!(launcher.terminate().success(), "{}", launcher.stderr());
}

/// Troupe's passthrough across namespaces (issue 30, item 1): robot 6665's
/// base in one stack's namespace served as robot 7000's in another stack's,
/// on the first one's router. Odometry comes through, a command moves r0,
/// and when the first stack's Stage dies 7000's base leaves and comes back
/// with it.
#[test]
fn a_passthrough_relays_a_device_of_another_namespace() {
    use troupe_client::Client;
    let world = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds/simple.world");
    let cfg_a = temp_cfg(
        "ns-a",
        &format!(
            "driver ( name \"stage\" provides [\"simulation:0\"] worldfile \"{}\" )\n\
             driver ( name \"stage\" provides [\"position2d:0\"] model \"r0\" )\n",
            world.canonicalize().unwrap().display()
        ),
    );
    let (mut a, endpoint, ns_a) = launch(&cfg_a, &["--no-bridge"]);
    let cfg_b = temp_cfg(
        "ns-b",
        &format!(
            "driver ( name \"passthrough\" requires [\"position2d:0\"] provides [\"7000:position2d:0\"] namespace \"{ns_a}\" )\n"
        ),
    );
    let ns_b = troupe_tests::unique_namespace("launch");
    let mut b = Proc::troupe(
        "launch-b",
        &strings(&[
            "--namespace",
            &ns_b,
            "--connect",
            &endpoint,
            "launch",
            cfg_b.to_str().unwrap(),
            "--no-bridge",
        ]),
    );
    let session = client_at(&endpoint, &ns_b);
    troupe_tests::wait_live(&session, &["7000:position2d:0"]);
    let tokens = token_events(&session);
    let robot = Client::with_session(session.clone(), 7000);
    drives_through_7000(&robot);

    // The first stack's Stage dies: 7000's base leaves, then comes back
    // once that stack's launcher has restarted it.
    kill_and_see_it_return(a.child.id(), "stage", &tokens, "robot/7000/position2d/0/");
    assert!(b.terminate().success(), "{}", b.stderr());
    assert!(a.terminate().success(), "{}", a.stderr());
}

#[test]
fn a_second_launch_on_a_taken_port_says_what_holds_it_and_what_to_do() {
    let cfg = temp_cfg("second", STACK);
    let (mut first, endpoint, ns) = launch(&cfg, &["--no-bridge"]);
    let second = |listen: &str| {
        troupe_output(&strings(&[
            "--namespace",
            &ns,
            "launch",
            cfg.to_str().unwrap(),
            "--listen",
            listen,
            "--no-bridge",
        ]))
    };
    let (st, _, err) = second(&endpoint);
    assert!(!st.success());
    assert!(
        err.contains(&format!("a Zenoh router is already running on {endpoint}"))
            && err.contains(&format!("join it with `--connect {endpoint}`"))
            && err.contains("--namespace NS")
            && !err.contains("no Zenoh router answers"),
        "{err}"
    );
    first.terminate();

    let held = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = held.local_addr().unwrap().port();
    let (st, _, err) = second(&format!("tcp/127.0.0.1:{port}"));
    assert!(!st.success());
    assert!(
        err.contains(&format!(
            "tcp/127.0.0.1:{port} is taken by another program (not a Zenoh router)"
        )),
        "{err}"
    );
}

/// The inodes of the sockets `pid` holds.
fn socket_inodes(pid: u32) -> std::collections::BTreeSet<u64> {
    let Ok(fds) = std::fs::read_dir(format!("/proc/{pid}/fd")) else {
        return Default::default();
    };
    fds.flatten()
        .filter_map(|fd| std::fs::read_link(fd.path()).ok())
        .filter_map(|l| {
            let l = l.to_string_lossy().into_owned();
            l.strip_prefix("socket:[")?.strip_suffix(']')?.parse().ok()
        })
        .collect()
}

/// A TCP socket of this network namespace as /proc/net/tcp{,6} lists it:
/// its inode, and its local and remote addresses and ports (addresses in
/// hex, in host byte order, as /proc spells them).
struct Socket {
    inode: u64,
    local: (String, u16),
    remote: (String, u16),
}

/// Every TCP socket of this network namespace in `state` (as /proc
/// spells it: `0A` listening, `01` established).
fn sockets(state: &str) -> Vec<Socket> {
    let end = |a: &str| {
        let (addr, port) = a.split_once(':').unwrap_or_default();
        (addr.to_owned(), u16::from_str_radix(port, 16).unwrap_or(0))
    };
    let mut out = Vec::new();
    for table in ["/proc/net/tcp", "/proc/net/tcp6"] {
        let text = std::fs::read_to_string(table).unwrap();
        for row in text.lines().skip(1) {
            let f: Vec<&str> = row.split_whitespace().collect();
            // sl, local address, remote address, state, …, inode
            if f.len() > 9 && f[3] == state {
                out.push(Socket {
                    inode: f[9].parse().unwrap_or(0),
                    local: end(f[1]),
                    remote: end(f[2]),
                });
            }
        }
    }
    out
}

/// 127.0.0.0/8 or ::1 (or ::ffff:127.x), as /proc/net spells them.
fn loopback(hex: &str) -> bool {
    match hex.len() {
        8 => hex.ends_with("7F"),
        32 => {
            hex == "00000000000000000000000001000000"
                || (hex.starts_with("0000000000000000FFFF0000") && hex.ends_with("7F"))
        }
        _ => false,
    }
}

#[test]
fn a_launch_and_its_viewers_listen_on_this_host_only() {
    // Nothing may be reached from the LAN that the user did not ask for: the
    // nodes', the view's and the Foxglove server's Zenoh sessions listen on
    // loopback, as the router, the bridge and the two pages were asked to.
    let cfg = temp_cfg("loopback", STACK);
    let ns = troupe_tests::unique_namespace("loopback");
    let mut launcher =
        troupe_tests::launch(&ns, &cfg, &["--view=127.0.0.1:0", "--foxglove=127.0.0.1:0"]);
    let lines = launcher.lines();
    let (mut router, mut viewers) = (None, 0);
    let deadline = Instant::now() + DEADLINE;
    while router.is_none() || viewers < 2 {
        let left = deadline.saturating_duration_since(Instant::now());
        let line = lines.recv_timeout(left).expect("the launcher's lines");
        if let Some(rest) = line.strip_prefix("troupe launch: router listening on ") {
            router = rest.split_whitespace().next().map(str::to_owned);
        } else if line.starts_with("troupe view: ") || line.starts_with("troupe foxglove: ") {
            viewers += 1;
        }
    }
    let s = client_at(&router.unwrap(), &ns);
    let tokens = token_events(&s);
    until_up(&tokens, 2, deadline);

    let pid = launcher.child.id();
    let mut pids = children(pid, "troupe");
    assert_eq!(pids.len(), 4, "dummy, rangertolaser, view and foxglove");
    pids.push(pid);
    let links = Links::now();
    let mut seen = Vec::new();
    for p in &pids {
        let cmd = cmdline(*p);
        let ours = links.listening_of(*p);
        assert!(!ours.is_empty(), "{cmd}: listens on nothing");
        for s in ours {
            let a = &s.local.0;
            assert!(loopback(a), "{cmd}: listens on {a} (not this host only)");
        }
        seen.push(cmd);
    }
    assert!(
        seen.iter().any(|c| c.contains(" foxglove ")) && seen.iter().any(|c| c.contains(" view ")),
        "{seen:?}"
    );
    assert!(launcher.terminate().success(), "{}", launcher.stderr());
}

#[test]
fn with_mode_client_a_launch_s_nodes_listen_on_nothing_and_send_through_the_router() {
    // `--mode client` (and `--lease`) reach the nodes of a launch on its
    // embedded router: each links to the router alone and listens on
    // nothing, and rangertolaser still takes dummy's ranger, through the
    // router.
    use troupe_msgs::{keys, laser, Device, Interface};
    use troupe_node::zenoh::Wait;
    let cfg = temp_cfg("clients", STACK);
    let (mut launcher, endpoint, ns) = launch(&cfg, &["--mode", "client", "--lease", "7"]);
    let s = client_at(&endpoint, &ns);
    let tokens = token_events(&s);
    let deadline = Instant::now() + DEADLINE;
    until_up(&tokens, 2, deadline);
    let scans = s
        .declare_subscriber(keys::data(&Device::new(6665, Interface::Laser, 0)))
        .wait()
        .unwrap();
    let scan = scans
        .recv_deadline(deadline)
        .unwrap()
        .expect("a laser scan from rangertolaser");
    troupe_msgs::decode::<laser::Scan>(&scan.payload().to_bytes()).expect("a scan");
    let router = launcher.child.id();
    let nodes = children(router, "troupe");
    assert_eq!(nodes.len(), 2, "dummy and rangertolaser: {nodes:?}");
    let links = Links::now();
    for n in &nodes {
        let cmd = cmdline(*n);
        assert!(cmd.contains(" --mode client --lease 7 "), "{cmd}");
        assert!(links.one_way(*n, router), "{cmd}: no link to the router");
        let listens: Vec<_> = links.listening_of(*n).iter().map(|s| &s.local).collect();
        assert!(listens.is_empty(), "{cmd}: a client listens on {listens:?}");
    }
    assert!(!links.between(nodes[0], nodes[1]), "the clients linked");
    assert!(launcher.terminate().success(), "{}", launcher.stderr());
}

/// This network namespace's TCP links, listening and established, as
/// one read of /proc sees them.
struct Links {
    listening: Vec<Socket>,
    established: Vec<Socket>,
}

impl Links {
    fn now() -> Links {
        Links {
            listening: sockets("0A"),
            established: sockets("01"),
        }
    }

    /// The sockets process `pid` listens on.
    fn listening_of(&self, pid: u32) -> Vec<&Socket> {
        let mine = socket_inodes(pid);
        self.listening
            .iter()
            .filter(|s| mine.contains(&s.inode))
            .collect()
    }

    /// Whether process `a` holds a link to a port process `b` listens on.
    fn one_way(&self, a: u32, b: u32) -> bool {
        let ports: Vec<u16> = self.listening_of(b).iter().map(|s| s.local.1).collect();
        let mine = socket_inodes(a);
        self.established.iter().any(|s| {
            mine.contains(&s.inode) && loopback(&s.remote.0) && ports.contains(&s.remote.1)
        })
    }

    /// Whether either of `a` and `b` holds a link to the other.
    fn between(&self, a: u32, b: u32) -> bool {
        self.one_way(a, b) || self.one_way(b, a)
    }
}

#[test]
fn a_launch_s_nodes_link_to_each_other_and_to_the_router() {
    // Data takes the shortest path: each node is a peer that learns of the
    // others through the launcher's router (gossip) and links to them, so
    // that rangertolaser takes dummy's ranger over one link, not two.
    let cfg = temp_cfg("direct", STACK);
    let (mut launcher, endpoint, ns) = launch(&cfg, &[]);
    let s = client_at(&endpoint, &ns);
    let tokens = token_events(&s);
    let deadline = Instant::now() + DEADLINE;
    until_up(&tokens, 2, deadline);
    let router = launcher.child.id();
    let nodes = children(router, "troupe");
    assert_eq!(nodes.len(), 2, "dummy and rangertolaser: {nodes:?}");
    // The link between the nodes comes once gossip has named one to the other.
    let links = loop {
        let links = Links::now();
        if links.between(nodes[0], nodes[1]) {
            break links;
        }
        assert!(
            Instant::now() < deadline,
            "no link between the nodes {nodes:?} within {DEADLINE:?}"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    for n in &nodes {
        assert!(
            links.one_way(*n, router),
            "node {n} has no link to the router"
        );
    }
    assert!(launcher.terminate().success(), "{}", launcher.stderr());
}

/// A camera frame (Player's dummy: 320 x 240 RGB, 230 KB) from a driver
/// process reaches a subscriber in another process through shared memory,
/// Zenoh's buffer handed over, not copied through a socket; with
/// `--no-shm`, through the network (ARCHITECTURE.md, "Big samples"). (The
/// first frames of a process may go through the network while Zenoh makes
/// its pool.)
#[test]
fn a_big_sample_reaches_another_process_through_shared_memory_unless_told_not_to() {
    use troupe_msgs::{camera, codec, keys, Device, Interface};
    use troupe_node::zenoh::Wait;
    let cfg = temp_cfg(
        "shm",
        "driver ( name \"dummy\" provides [\"camera:0\"] rate 20 )\n",
    );
    for (extra, shared) in [(&[][..], true), (&["--no-shm"][..], false)] {
        let (mut launcher, endpoint, ns) = launch(&cfg, extra);
        let session = client_at(&endpoint, &ns);
        let frames = session
            .declare_subscriber(keys::data(&Device::new(6665, Interface::Camera, 0)))
            .wait()
            .unwrap();
        let next = || {
            let s = frames
                .recv_timeout(DEADLINE)
                .unwrap()
                .expect("a frame within the deadline");
            let frame = codec::decode::<camera::Data>(&s.payload().to_bytes()).unwrap();
            assert_eq!((frame.msg.width, frame.msg.height), (320, 240));
            assert_eq!(frame.msg.image.len(), 320 * 240 * 3);
            s.payload().as_shm().is_some()
        };
        if shared {
            let deadline = Instant::now() + DEADLINE;
            while !next() {
                assert!(Instant::now() < deadline, "no frame through shared memory");
            }
        } else {
            for _ in 0..10 {
                assert!(
                    !next(),
                    "launched with --no-shm: a frame through shared memory"
                );
            }
        }
        drop(frames);
        drop(session);
        assert!(launcher.terminate().success(), "{}", launcher.stderr());
    }
}
