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
