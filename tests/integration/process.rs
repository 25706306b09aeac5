//! `troupe` processes started as a user would, over a `troupe router` process.

use troupe_tests::{strings, troupe_output, Proc, TestNet};

/// A `troupe router` child on an ephemeral loopback port; returns it and its endpoint.
fn router() -> (Proc, String) {
    let mut r = Proc::troupe(
        "router",
        &strings(&["router", "--listen", "tcp/127.0.0.1:0", "--no-multicast"]),
    );
    let endpoint = r.endpoint("troupe router listening on");
    (r, endpoint)
}

fn with_net(net_args: &[String], args: &[&str]) -> Vec<String> {
    let mut v = net_args.to_vec();
    v.extend(strings(args));
    v
}

#[test]
fn two_processes_see_each_other_and_stop_cleanly() {
    let (_router, endpoint) = router();
    let ns = troupe_tests::unique_namespace("proc");
    let net: Vec<String> = strings(&["--connect", &endpoint, "--no-multicast", "--namespace", &ns]);
    let node_net = with_net(&net, &["--listen", "tcp/127.0.0.1:0"]);
    let mut dummy = Proc::troupe(
        "dummy",
        &with_net(
            &node_net,
            &["node", "dummy", "--provides", "ranger:0", "-o", "rate=20"],
        ),
    );
    let mut conv = Proc::troupe(
        "rangertolaser",
        &with_net(
            &node_net,
            &[
                "node",
                "rangertolaser",
                "--requires",
                "ranger:0",
                "--provides",
                "laser:0",
            ],
        ),
    );
    // Wait for both devices through the same router, as a user's tool would.
    let probe = TestNet {
        router: troupe_node::ZenohArgs {
            connect: vec![endpoint.clone()],
            no_multicast: true,
            ..Default::default()
        }
        .open(troupe_node::Mode::Client)
        .unwrap(),
        endpoint: endpoint.clone(),
        namespace: ns.clone(),
    };
    probe.wait_live(&["6665:ranger:0", "6665:laser:0"]);

    let (st, out, err) = troupe_output(&with_net(&net, &["list"]));
    assert!(st.success(), "{err}");
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines.len(), 2, "{out}");
    assert!(
        lines[0].starts_with("robot/6665")
            && lines[0].contains("laser:0")
            && lines[0].contains("rangertolaser")
            && lines[0].ends_with("ready"),
        "{out}"
    );
    assert!(
        lines[1].contains("ranger:0") && lines[1].contains("dummy"),
        "{out}"
    );

    let (st, out, err) = troupe_output(&with_net(
        &net,
        &["echo", "laser:0", "--count", "2", "--json"],
    ));
    assert!(st.success(), "{err}");
    let samples: Vec<serde_json::Value> = out
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(samples.len(), 2);
    assert_eq!(samples[1]["type"], "LaserScan");
    assert_eq!(samples[1]["msg"]["ranges"].as_array().unwrap().len(), 361);

    let (st, out, _) = troupe_output(&with_net(&net, &["hz", "ranger:0", "--count", "2"]));
    assert!(st.success());
    let last = out.lines().last().unwrap_or_default().to_owned();
    let hz: f64 = last
        .strip_prefix("rate: ")
        .and_then(|r| r.split(' ').next())
        .and_then(|r| r.parse().ok())
        .unwrap_or_else(|| panic!("no rate in {out:?}"));
    assert!((10.0..40.0).contains(&hz), "{out}");

    assert!(
        conv.terminate().success(),
        "rangertolaser: {}",
        conv.stderr()
    );
    assert!(dummy.terminate().success(), "dummy: {}", dummy.stderr());
}

#[test]
fn bad_input_gets_clear_errors_not_panics() {
    let cases: &[(&[&str], &str)] = &[
        (
            &["node", "nosuch"],
            "driver `nosuch` is not available in Troupe; available: dummy, rangertolaser",
        ),
        (
            &["node", "dummy", "--provides", "map:0"],
            "cannot provide 6665:map:0",
        ),
        (&["node", "dummy", "--provides", "laser:x"], "`x`"),
        (
            &[
                "node",
                "dummy",
                "--section",
                "{\"name\":\"dummy\",\"provides\":[\"::\"]}",
            ],
            "`::`",
        ),
        (&["echo", "lazer:0"], "unknown interface `lazer`"),
        (&["echo", "some/key"], "`some/key` is not a device key"),
    ];
    for (args, expected) in cases {
        let (st, _, err) = troupe_output(&strings(args));
        assert!(!st.success(), "{args:?} should fail");
        assert!(err.contains(expected), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
}

/// A loopback port nothing listens on now (bound, then let go).
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port()
}

#[test]
fn with_reconnect_start_order_does_not_matter_and_ready_says_when_devices_are_live() {
    let ns = troupe_tests::unique_namespace("reconnect");
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let net = strings(&["--connect", &endpoint, "--no-multicast", "--namespace", &ns]);
    let ready = |devices: &[&str]| troupe_output(&with_net(&net, &[&["ready"], devices].concat()));

    // No router yet: `ready` fails at once, saying so.
    let (status, _, err) = ready(&["ranger:0"]);
    assert!(!status.success());
    assert!(err.contains("no Zenoh router answers"), "{err}");
    // So does `record`, though it joins as a peer (which alone would go on
    // hearing nothing).
    let out = std::env::temp_dir().join(format!("{ns}.mcap"));
    let (status, _, err) = troupe_output(&with_net(
        &net,
        &["record", "-o", out.to_str().unwrap(), "--duration", "5"],
    ));
    assert!(!status.success());
    assert!(err.contains("no Zenoh router answers"), "{err}");

    // A launcher and a node that keep trying, started before the router.
    let plan = std::env::temp_dir().join(format!("{ns}.toml"));
    std::fs::write(
        &plan,
        "[[node]]\nname = \"laser\"\ndriver = \"rangertolaser\"\nrequires = [{ device = \"robot/6665/ranger/0\" }]\nprovides = [{ device = \"robot/6665/laser/0\" }]\n\n[launch]\nexternal = [\"robot/6665/ranger/0\"]\n",
    )
    .unwrap();
    let mut launcher = Proc::troupe(
        "launch",
        &with_net(
            &net,
            &[
                "--reconnect",
                "launch",
                plan.to_str().unwrap(),
                "--no-bridge",
            ],
        ),
    );
    let mut dummy = Proc::troupe(
        "dummy",
        &with_net(
            &net,
            &[
                "--reconnect",
                "--listen",
                "tcp/127.0.0.1:0",
                "node",
                "dummy",
                "--provides",
                "ranger:0",
                "-o",
                "rate=20",
            ],
        ),
    );
    let mut router = Proc::troupe(
        "router",
        &strings(&["router", "--listen", &endpoint, "--no-multicast"]),
    );
    router.first_line();
    let (status, out, err) = troupe_output(&with_net(
        &net,
        &["ready", "ranger:0", "laser:0", "--wait", "20"],
    ));
    assert!(status.success(), "{out}{err}");
    assert_eq!(out.trim(), "ready: all 2 devices live");
    // A device nobody provides is named.
    let (status, _, err) = ready(&["ranger:0", "6666:laser:3"]);
    assert!(!status.success());
    assert!(
        err.contains("not live: 6666:laser:3 (1 of 2 devices live)"),
        "{err}"
    );
    assert!(dummy.terminate().success(), "{}", dummy.stderr());
    assert!(launcher.terminate().success(), "{}", launcher.stderr());
    let _ = std::fs::remove_file(&plan);
}

#[test]
fn a_launcher_waiting_for_its_router_stops_cleanly_on_sigterm() {
    // As a container's PID 1 would be asked to, before any router is up.
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let mut launcher = Proc::troupe(
        "launch",
        &strings(&[
            "--connect",
            &endpoint,
            "--no-multicast",
            "--reconnect",
            "launch",
            concat!(env!("CARGO_MANIFEST_DIR"), "/../worlds/laser.cfg"),
            "--no-bridge",
        ]),
    );
    let mut bridge = Proc::troupe(
        "bridge",
        &strings(&[
            "--connect",
            &endpoint,
            "--no-multicast",
            "--reconnect",
            "bridge",
            "-p",
            "6665=127.0.0.1:0",
        ]),
    );
    // Both say they are waiting before the signal comes.
    let waiting = |p: &mut Proc| {
        let err = p.child.stderr.take().expect("stderr");
        let mut lines = std::io::BufRead::lines(std::io::BufReader::new(err));
        lines
            .find(|l| {
                l.as_ref()
                    .is_ok_and(|l| l.contains("waiting until it answers"))
            })
            .expect("a line saying it waits for the router")
            .ok();
    };
    waiting(&mut launcher);
    waiting(&mut bridge);
    assert!(launcher.terminate().success());
    assert!(bridge.terminate().success());
}

/// `troupe bridge FLAGS…` on `net`; the process and the address it serves robot 6665 on.
fn bridge_on(net: &TestNet, flags: &[&str]) -> (Proc, std::net::SocketAddr) {
    let mut args = net.child_args();
    args.extend(strings(&["bridge"]));
    args.extend(strings(flags));
    let mut p = Proc::troupe("bridge", &args);
    let line = p.first_line();
    let addr = line
        .trim()
        .strip_prefix("troupe bridge: robot 6665 on ")
        .and_then(|a| a.parse().ok())
        .unwrap_or_else(|| panic!("bridge said {line:?}"));
    (p, addr)
}

/// Connects and reads what comes first: the 32-byte banner, or nothing.
fn first_bytes(addr: std::net::SocketAddr) -> Vec<u8> {
    use std::io::Read;
    let s = std::net::TcpStream::connect(addr).expect("connecting to the bridge");
    s.set_read_timeout(Some(troupe_tests::DEADLINE)).unwrap();
    let mut got = Vec::new();
    let _ = s.take(32).read_to_end(&mut got);
    got
}

#[test]
fn the_bridge_warns_when_open_beyond_loopback_and_refuses_clients_outside_its_allow_list() {
    let net = TestNet::new("bridge-allow");
    // Every interface, no list: anyone may connect, and the log says so.
    let (mut open, addr) = bridge_on(&net, &["-p", "6665=0.0.0.0:0"]);
    let local = std::net::SocketAddr::from(([127, 0, 0, 1], addr.port()));
    assert!(first_bytes(local).starts_with(b"Player v.3"));
    let err = open.stderr();
    assert!(
        err.contains("Player's protocol has no authentication"),
        "{err}"
    );

    // A list without this machine: closed before the banner, counted.
    let (mut closed, addr) = bridge_on(&net, &["-p", "6665=127.0.0.1:0", "--allow", "10.0.0.0/8"]);
    assert!(first_bytes(addr).is_empty());
    assert!(first_bytes(addr).is_empty());
    let err = closed.stderr();
    assert_eq!(
        err.matches("refused a client from 127.0.0.1").count(),
        1,
        "{err}"
    );
    assert!(
        err.contains("refused 2 connections from 1 addresses outside --allow"),
        "{err}"
    );

    // A list with it: served.
    let (_served, addr) = bridge_on(&net, &["-p", "6665=127.0.0.1:0", "--allow", "127.0.0.0/8"]);
    assert!(first_bytes(addr).starts_with(b"Player v.3"));

    // A malformed network is refused by name.
    let (status, _, err) = troupe_output(&strings(&["bridge", "--allow", "10.0.0.0/40"]));
    assert!(!status.success());
    assert!(err.contains("`10.0.0.0/40` is not a network"), "{err}");
}

#[test]
fn a_tls_fleet_admits_its_own_certificates_only_and_each_identity_does_only_what_it_may() {
    use troupe_node::zenoh::Wait;
    let dir = std::env::temp_dir().join(troupe_tests::unique_namespace("keys"));
    let (ours, theirs) = (dir.join("ours"), dir.join("theirs"));
    let ns = troupe_tests::unique_namespace("tls");
    for (d, who) in [
        (
            &ours,
            &[
                "--namespace",
                &ns,
                "--hosts",
                "hosta:6665,hostb:6666",
                "--operators",
                "ops:6665",
                "--viewers",
                "eye",
            ][..],
        ),
        (&theirs, &["--hosts", "hosta:6665"][..]),
    ] {
        let mut args = strings(&["fleet-keys", d.to_str().unwrap()]);
        args.extend(strings(who));
        let (status, _, err) = troupe_output(&args);
        assert!(status.success(), "{err}");
    }
    let cfg = |d: &std::path::Path, who: &str| d.join(format!("{who}.json5")).display().to_string();
    // The router listens on TLS only, on a free port of this machine. Our
    // members' configs join the fleet's namespace, and the router's access
    // rules name keys under it.
    let mut router = Proc::troupe(
        "router",
        &strings(&[
            "--zenoh-config",
            &cfg(&ours, "router"),
            "router",
            "--listen",
            "tls/127.0.0.1:0",
        ]),
    );
    let endpoint = router.endpoint("troupe router listening on");
    assert!(endpoint.starts_with("tls/127.0.0.1:"), "{endpoint}");
    // Certificates name the router `router`, `localhost` and 127.0.0.1.
    let at = endpoint.replace("127.0.0.1", "localhost");
    let net = |who: Option<String>| {
        let mut v = strings(&["--connect", &at]);
        if let Some(c) = who {
            v.extend(["--zenoh-config".to_owned(), c]);
        }
        v
    };
    let mut node = Proc::troupe(
        "dummy",
        &with_net(
            &net(Some(cfg(&ours, "hosta"))),
            &["node", "dummy", "--provides", "ranger:0", "-o", "rate=20"],
        ),
    );
    // A viewer lists and reads.
    let (status, out, err) = troupe_output(&with_net(
        &net(Some(cfg(&ours, "eye"))),
        &["ready", "ranger:0", "--wait", "20"],
    ));
    assert!(status.success(), "{out}{err}");
    let (status, out, err) = troupe_output(&with_net(
        &net(Some(cfg(&ours, "eye"))),
        &["echo", "ranger:0", "--count", "1"],
    ));
    assert!(
        status.success() && out.contains("robot/6665/ranger/0"),
        "{out}{err}"
    );

    // What each may send, seen by a subscriber: a message that passes
    // arrives before one sent after it; a denied one never does. Each
    // sender's put is followed by a round trip through the router, so the
    // router has routed it before the next sender speaks.
    let session = |who: &str| {
        troupe_node::ZenohArgs {
            connect: vec![at.clone()],
            zenoh_config: Some(cfg(&ours, who).into()),
            ..Default::default()
        }
        .open(troupe_node::Mode::Client)
        .unwrap_or_else(|e| panic!("{who}: {e}"))
    };
    let (tap, eye, ops, hosta, hostb) = (
        session("hosta"),
        session("eye"),
        session("ops"),
        session("hosta"),
        session("hostb"),
    );
    // A round trip through the router: what `s` sent before is routed.
    let sync = |s: &troupe_node::zenoh::Session| {
        let _ = s
            .liveliness()
            .get("robot/**")
            .wait()
            .unwrap()
            .iter()
            .count();
    };
    type Tries<'a> = [(&'a troupe_node::zenoh::Session, &'a str)];
    let first_at = |tap: &troupe_node::zenoh::Session, key: &str, tries: &Tries| -> String {
        let sub = tap.declare_subscriber(key).wait().unwrap();
        sync(tap);
        for (s, text) in tries {
            s.put(key, *text).wait().unwrap();
            sync(s);
        }
        let got = sub
            .recv_deadline(std::time::Instant::now() + troupe_tests::DEADLINE)
            .unwrap()
            .expect("a message");
        String::from_utf8_lossy(&got.payload().to_bytes()).into_owned()
    };
    let first = |key: &str, tries: &Tries| first_at(&tap, key, tries);
    // A viewer's command does not reach the robot; an operator's does.
    let cmd = "robot/6665/position2d/0/cmd/vel";
    assert_eq!(first(cmd, &[(&eye, "eye"), (&ops, "ops")]), "ops");
    // A robot host publishes under its own robots' keys only.
    let data = "robot/6666/laser/0";
    assert_eq!(
        first(data, &[(&hosta, "hosta"), (&hostb, "hostb")]),
        "hostb"
    );
    // An operator granted robot 6665 cannot command 6666; that robot's host can.
    let cmd6 = "robot/6666/position2d/0/cmd/vel";
    assert_eq!(first(cmd6, &[(&ops, "ops"), (&hostb, "hostb")]), "hostb");
    // Members joined as peers that listen (`--mode peer --listen …`), a
    // viewer's and a host's, still meet the others only through the
    // router, whose rules so hold on every path: the fleet's configs turn
    // gossip off (the router tells no one where the others listen) and
    // give members no certificate to serve TLS with. (Two members that are
    // both peers hear nothing of each other: the router does not broker
    // between peers it has no link state of, so a fleet's processes are
    // its clients.)
    let peer = |who: &str| {
        troupe_node::ZenohArgs {
            connect: vec![at.clone()],
            listen: vec!["tcp/127.0.0.1:0".into()],
            zenoh_config: Some(cfg(&ours, who).into()),
            mode: Some(troupe_node::Mode::Peer),
            ..Default::default()
        }
        .open(troupe_node::Mode::Peer)
        .unwrap_or_else(|e| panic!("{who} as a peer: {e}"))
    };
    let (host_peer, eye_peer, ops_peer) = (peer("hosta"), peer("eye"), peer("ops"));
    assert_eq!(
        first_at(&tap, cmd, &[(&eye_peer, "eye"), (&ops_peer, "ops")]),
        "ops"
    );
    assert_eq!(
        first_at(&host_peer, cmd, &[(&eye, "eye"), (&ops, "ops")]),
        "ops"
    );
    // A viewer may ask a simulator for its world (`troupe view`), not
    // move its models: the router drops the second query, which so gets
    // no answer before its timeout.
    let _sim = hosta
        .declare_queryable("robot/6665/simulation/0/req/*")
        .callback(|q| {
            let key = q.key_expr().clone();
            let _ = q.reply(key, "answer").wait();
        })
        .wait()
        .unwrap();
    sync(&hosta);
    let answers = |key: &str| {
        eye.get(key)
            .timeout(std::time::Duration::from_secs(2))
            .wait()
            .unwrap()
            .iter()
            .filter(|r| r.result().is_ok())
            .count()
    };
    assert_eq!(answers("robot/6665/simulation/0/req/world"), 1);
    assert_eq!(answers("robot/6665/simulation/0/req/set_pose2d"), 0);
    // `troupe view` joined as the viewer says so, in the fleet's
    // namespace, and refuses to command rather than send what the router
    // would drop unseen.
    let mut view = Proc::troupe(
        "view",
        &with_net(&net(Some(cfg(&ours, "eye"))), &["view", "--port", "0"]),
    );
    let line = view.first_line();
    let base = line
        .trim()
        .strip_prefix("troupe view: ")
        .expect("the view's address");
    let world = crate::view::json(base, "/api/world");
    assert_eq!(world["looking_only"], "eye", "{world}");
    assert_eq!(world["namespace"], ns.as_str(), "{world}");
    let (code, why) = crate::view::post(
        base,
        &serde_json::json!({ "device": "6665:position2d:0", "vel": [0.2, 0.0, 0.0] }),
    );
    assert_eq!(code, 403, "{why}");
    assert!(why.contains("viewer `eye`"), "{why}");
    assert!(view.terminate().success(), "{}", view.stderr());
    // So is `troupe foxglove`: joined as the viewer, it offers its clients
    // no publishing; as an operator, it does.
    for (who, publishes) in [("eye", false), ("ops", true)] {
        let mut fox = Proc::troupe(
            "foxglove",
            &with_net(&net(Some(cfg(&ours, who))), &["foxglove", "--port", "0"]),
        );
        let line = fox.first_line();
        let url = line
            .split_whitespace()
            .find(|w| w.starts_with("ws://"))
            .unwrap_or_else(|| panic!("no address in {line:?}"));
        let capabilities = foxglove_capabilities(url);
        assert_eq!(
            capabilities.iter().any(|c| c == "clientPublish"),
            publishes,
            "{who}: {capabilities:?}"
        );
        assert!(fox.terminate().success(), "{}", fox.stderr());
    }

    // Another authority's certificate, none, or plain TCP: refused, and told why.
    let (status, _, err) = troupe_output(&with_net(
        &net(Some(cfg(&theirs, "hosta"))),
        &["ready", "ranger:0"],
    ));
    assert!(!status.success());
    assert!(err.contains("no Zenoh router accepted a TLS link"), "{err}");
    assert!(err.contains("same `troupe fleet-keys` authority"), "{err}");
    let (status, _, err) = troupe_output(&with_net(&net(None), &["ready", "ranger:0"]));
    assert!(!status.success());
    assert!(err.contains("this host has no certificate"), "{err}");
    let plain = endpoint.replace("tls/", "tcp/");
    let (status, _, err) = troupe_output(&strings(&["--connect", &plain, "ready"]));
    assert!(!status.success());
    assert!(
        err.contains(&format!(
            "something listens at {plain} but does not answer as a plain-TCP Zenoh router"
        )) && err.contains("takes TLS only"),
        "{err}"
    );
    // A router name that does not resolve here says so, and what to give instead.
    let (status, _, err) = troupe_output(&strings(&[
        "--connect",
        "tls/no-such-router.invalid:7447",
        "ready",
    ]));
    assert!(!status.success());
    assert!(
        err.contains("the name `no-such-router.invalid` in tls/no-such-router.invalid:7447 does not resolve on this machine")
            && err.contains("--connect tls/localhost:7447"),
        "{err}"
    );

    // A wrong password is refused; so is a member struck from the router's
    // `passwords` (how a lost host is shut out: Zenoh's TLS has no
    // revocation list), while the others still get in.
    let dictionary = std::fs::read_to_string(ours.join("passwords")).unwrap();
    let password = |who: &str| {
        dictionary
            .lines()
            .find_map(|l| l.strip_prefix(&format!("{who}:")))
            .unwrap_or_else(|| panic!("{who} not in {dictionary}"))
            .to_owned()
    };
    let wrong = dir.join("wrong.json5");
    let text = std::fs::read_to_string(cfg(&ours, "hosta")).unwrap();
    assert!(text.contains(&password("hosta")));
    std::fs::write(&wrong, text.replace(&password("hosta"), "0123456789abcdef")).unwrap();
    let (status, _, err) = troupe_output(&with_net(
        &net(Some(wrong.display().to_string())),
        &["ready"],
    ));
    assert!(!status.success());
    assert!(
        err.contains("user and password must be in the router's `passwords`"),
        "{err}"
    );
    let struck = dir.join("struck");
    std::fs::create_dir_all(&struck).unwrap();
    std::fs::copy(cfg(&ours, "router"), cfg(&struck, "router")).unwrap();
    let kept: String = dictionary
        .lines()
        .filter(|l| !l.starts_with("hostb:"))
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(struck.join("passwords"), kept).unwrap();
    let mut router2 = Proc::troupe(
        "router2",
        &strings(&[
            "--zenoh-config",
            &cfg(&struck, "router"),
            "router",
            "--listen",
            "tls/127.0.0.1:0",
        ]),
    );
    let at2 = router2
        .endpoint("troupe router listening on")
        .replace("127.0.0.1", "localhost");
    for (who, admitted) in [("hosta", true), ("hostb", false)] {
        let (status, out, err) = troupe_output(&strings(&[
            "--connect",
            &at2,
            "--zenoh-config",
            &cfg(&ours, who),
            "ready",
        ]));
        assert_eq!(status.success(), admitted, "{who}: {out}{err}");
    }
    assert!(router2.terminate().success(), "{}", router2.stderr());

    // The key files are for their hosts only.
    use std::os::unix::fs::PermissionsExt;
    let mode = std::fs::metadata(cfg(&ours, "hosta"))
        .unwrap()
        .permissions()
        .mode();
    assert_eq!(mode & 0o077, 0, "{mode:o}");
    let mode = std::fs::metadata(ours.join("passwords"))
        .unwrap()
        .permissions()
        .mode();
    assert_eq!(mode & 0o077, 0, "{mode:o}");
    assert!(node.terminate().success(), "{}", node.stderr());
    let _ = std::fs::remove_dir_all(&dir);
}

/// The four lines of docs/fleets.md's "Securing a fleet", run as printed in a
/// fresh directory (with the repository's `worlds/` beside the keys), but
/// for two things a test must: the router on a free port (`--listen`, and
/// `--connect` for the others to it) and `echo --count 1` to end.
#[test]
fn the_secured_fleet_of_the_docs_runs_on_one_machine() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let lines: Vec<Vec<String>> = crate::docs::block("docs/fleets.md", "## Securing a fleet", "sh")
        .lines()
        .map(|l| {
            let l = l.split('#').next().unwrap_or("").trim();
            let words: Vec<&str> = l.split_whitespace().collect();
            assert_eq!(words.first(), Some(&"troupe"), "{l}");
            strings(&words[1..])
        })
        .collect();
    assert_eq!(lines.len(), 4, "{lines:?}");
    let dir = std::env::temp_dir().join(troupe_tests::unique_namespace("readme-keys"));
    std::fs::create_dir_all(&dir).unwrap();
    std::os::unix::fs::symlink(
        root.join("worlds").canonicalize().unwrap(),
        dir.join("worlds"),
    )
    .unwrap();
    let in_dir = |name: &str, args: Vec<String>| {
        let mut cmd = std::process::Command::new(troupe_tests::troupe_bin());
        cmd.args(args).current_dir(&dir);
        Proc::start(name, &mut cmd)
    };

    let mut keys = in_dir("fleet-keys", lines[0].clone());
    assert!(keys.wait().success(), "{}", keys.stderr());
    let mut router_args = lines[1].clone();
    router_args.extend(strings(&["--listen", "tls/127.0.0.1:0"]));
    let mut router = in_dir("router", router_args);
    let endpoint = router
        .endpoint("troupe router listening on")
        .replace("127.0.0.1", "localhost");
    let joined = |line: &[String]| {
        let mut v = strings(&["--connect", &endpoint]);
        v.extend(line.iter().cloned());
        v
    };
    let mut robot1 = in_dir("launch", joined(&lines[2]));
    let mut echo_args = joined(&lines[3]);
    echo_args.extend(strings(&["--count", "1"]));
    let (status, text, err) = in_dir("echo", echo_args).output();
    assert!(status.success(), "{err}\n{}", robot1.stderr());
    assert!(text.starts_with("robot/6665/laser/0  t="), "{text}");
    assert!(robot1.terminate().success(), "{}", robot1.stderr());
    router.terminate();
}

/// A Foxglove client of `troupe foxglove` at `url` (the SDK's subprotocol).
fn foxglove_client(
    url: &str,
) -> tungstenite::WebSocket<tungstenite::stream::MaybeTlsStream<std::net::TcpStream>> {
    use tungstenite::client::IntoClientRequest;
    let mut req = url.into_client_request().unwrap();
    req.headers_mut().insert(
        "Sec-WebSocket-Protocol",
        tungstenite::http::HeaderValue::from_static("foxglove.sdk.v1"),
    );
    tungstenite::connect(req).unwrap().0
}

/// The capabilities a Foxglove server offers, from the serverInfo it sends
/// first (protocol `foxglove.sdk.v1`).
fn foxglove_capabilities(url: &str) -> Vec<String> {
    let mut ws = foxglove_client(url);
    let info: serde_json::Value = match ws.read().unwrap() {
        tungstenite::Message::Text(t) => serde_json::from_str(&t).unwrap(),
        other => panic!("expected serverInfo, got {other:?}"),
    };
    assert_eq!(info["op"], "serverInfo", "{info}");
    let _ = ws.close(None);
    info["capabilities"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|c| c.as_str().map(str::to_owned))
        .collect()
}

/// The p50 of the row `name` in `bench latency`'s output, in µs, from
/// the line after `after`.
fn p50_of(out: &str, after: &str, name: &str) -> f64 {
    let rest = &out[out
        .find(after)
        .unwrap_or_else(|| panic!("no {after:?} in:\n{out}"))..];
    let line = rest
        .lines()
        .find(|l| l.trim_start().starts_with(name))
        .unwrap_or_else(|| panic!("no {name:?} row after {after:?} in:\n{out}"));
    let p50 = line.split("p50").nth(1).expect("a p50");
    p50.split_whitespace().next().unwrap().parse().unwrap()
}

#[test]
fn bench_latency_prints_its_floor_and_zenoh_at_its_fastest_beside_the_figures() {
    let (status, out, err) = troupe_output(&strings(&[
        "bench",
        "latency",
        "--samples",
        "50",
        "--warmup",
        "10",
    ]));
    assert!(status.success(), "bench latency failed:\n{out}\n{err}");
    for (after, name) in [
        ("troupe bench latency", "TCP round trip (the floor)"),
        ("troupe bench latency", "put/sub round trip"),
        ("troupe bench latency", "get/reply round trip"),
        ("Zenoh at its fastest", "TCP round trip, in turn"),
        ("Zenoh at its fastest", "put/sub round trip"),
    ] {
        let p50 = p50_of(&out, after, name);
        assert!(p50 > 0.0, "{name} after {after}: p50 {p50} µs in:\n{out}");
    }
    assert_eq!(
        out.matches("p50 against TCP").count(),
        2,
        "both ratios, the figures' and the fastest path's:\n{out}"
    );
    assert!(
        out.contains("Troupe's path against Zenoh's fastest, p50, same run: put/sub round trip"),
        "{out}"
    );
    // Zenoh settings reach both sides' sessions: a key Zenoh does not know
    // is refused, named.
    let (status, _, err) = troupe_output(&strings(&[
        "bench",
        "latency",
        "--samples",
        "5",
        "--warmup",
        "1",
        "--zenoh-set",
        "transport/no_such_key=1",
    ]));
    assert!(
        !status.success() && err.contains("--zenoh-set transport/no_such_key=1"),
        "{err}"
    );
    // A camera frame large enough for shared memory: both paths, and a
    // small sample beside them.
    let (status, out, err) = troupe_output(&strings(&[
        "bench",
        "latency",
        "--carry",
        "camera",
        "--size",
        "100000",
        "--samples",
        "20",
        "--warmup",
        "5",
    ]));
    assert!(status.success(), "bench latency failed:\n{out}\n{err}");
    assert!(
        out.contains("camera/data@1 payload")
            && out.contains("the samples through shared memory")
            && out.contains("same run, one sample one way p50 (throughput): over shared memory"),
        "{out}"
    );
    // One way by the clock both processes read, beside half a round trip.
    for after in ["tcp/127.0.0.1\n", "through shared memory\n"] {
        for name in ["one sample (round trip/2)", "one sample one way"] {
            let p50 = p50_of(&out, after, name);
            assert!(p50 > 0.0, "{name} after {after:?}: p50 {p50} µs in:\n{out}");
        }
    }
    assert_eq!(out.matches("  throughput ").count(), 3, "{out}");
}

/// A panic in any of a driver's hooks ends its process with status 101 and
/// the panic's message, for the supervisor to restart it: never a driver
/// hung with its devices still announced. A request's hook runs on Zenoh's
/// thread while the driver is idle (`Driver::quick`), where a panic used to
/// unwind that thread only.
#[test]
fn a_driver_that_panics_in_any_hook_exits_for_its_supervisor() {
    use troupe_msgs::codec::{self, Command, Request};
    use troupe_msgs::{keys, position2d, Device, Interface};
    use troupe_node::zenoh::Wait;
    let net = TestNet::new("panic");
    let dev = Device::new(6665, Interface::Position2d, 0);
    for hook in ["setup", "tick", "request", "command"] {
        let mut args = net.child_args();
        args.extend(strings(&[
            "node",
            "dummy",
            "--provides",
            "position2d:0",
            "-o",
            "rate=2",
            "-o",
            &format!("panic_in={hook}"),
        ]));
        let mut node = Proc::troupe(&format!("dummy-{hook}"), &args);
        let client = net.client();
        match hook {
            "request" => {
                net.wait_live(&["6665:position2d:0"]);
                let asked = client
                    .get(keys::req(&dev, position2d::GetGeom::NAME))
                    .payload(codec::encode(&position2d::GetGeom, 0.0))
                    .wait()
                    .unwrap();
                // No answer comes: the process is gone.
                assert!(asked.recv().is_err(), "the panicking hook answered");
            }
            "command" => {
                net.wait_live(&["6665:position2d:0"]);
                let cmd = position2d::CmdVel::default();
                client
                    .put(
                        keys::cmd(&dev, position2d::CmdVel::NAME),
                        codec::encode(&cmd, 0.0),
                    )
                    .wait()
                    .unwrap();
            }
            _ => {}
        }
        let status = node.wait();
        let err = node.stderr();
        assert_eq!(status.code(), Some(101), "{hook}: {status:?}\n{err}");
        assert!(
            err.contains("panicking in its")
                && err.contains("exiting (status 101) to be restarted"),
            "{hook}: {err}"
        );
    }
}

/// `troupe foxglove` stops cleanly on SIGTERM with clients attached (it
/// panicked in 2 of 6 tries, as the last clone of its session closed on
/// the WebSocket server's current-thread runtime, and still exited 0),
/// and a panic on any thread of a command fails it.
#[test]
fn foxglove_stops_cleanly_with_clients_attached() {
    let net = TestNet::new("fox-stop");
    let mut dummy = Proc::troupe(
        "dummy",
        &with_net(
            &net.child_args(),
            &["node", "dummy", "--provides", "laser:0", "-o", "rate=50"],
        ),
    );
    net.wait_live(&["6665:laser:0"]);
    for round in 0..3 {
        let mut fox = Proc::troupe(
            "foxglove",
            &with_net(&net.child_args(), &["foxglove", "--port", "0"]),
        );
        let line = fox.first_line();
        let url = line
            .split_whitespace()
            .find(|w| w.starts_with("ws://"))
            .unwrap_or_else(|| panic!("no address in {line:?}"));
        let clients: Vec<_> = (0..2)
            .map(|_| {
                let mut ws = foxglove_client(url);
                // serverInfo, then the laser's channel once it is heard.
                let mut advertised = false;
                while !advertised {
                    if let tungstenite::Message::Text(t) = ws.read().unwrap() {
                        advertised = t.contains("\"advertise\"") && t.contains("laser");
                    }
                }
                ws
            })
            .collect();
        let status = fox.terminate();
        let err = fox.stderr();
        assert!(
            status.success() && !err.contains("panicked"),
            "round {round}: {status:?}\n{err}"
        );
        drop(clients);
    }
    assert!(dummy.terminate().success());
}
