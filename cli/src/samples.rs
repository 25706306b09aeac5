//! This build against the repository's files: every compat cfg plans as
//! its golden file says (or fails as it says), the sample cfgs plan
//! cleanly, and the root docker-compose.yml is `troupe compose`'s output.
//! They live here because only the binary links every driver.

/// Golden tests: the plan (or the errors) of every cfg in ../shared/compat.
///
/// Set `TROUPE_BLESS=1` to rewrite the expected files after a deliberate change.
mod golden {
    use std::path::{Path, PathBuf};

    use troupe_launch::plan;

    fn compat() -> Option<PathBuf> {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/compat");
        dir.is_dir().then(|| dir.canonicalize().unwrap_or(dir))
    }

    fn cfgs(dir: &Path, out: &mut Vec<PathBuf>) {
        let mut entries: Vec<_> = std::fs::read_dir(dir)
            .unwrap()
            .flatten()
            .map(|e| e.path())
            .collect();
        entries.sort();
        for p in entries {
            if p.is_dir() {
                cfgs(&p, out);
            } else if p.extension().is_some_and(|e| e == "cfg") {
                out.push(p);
            }
        }
    }

    #[test]
    fn every_compat_cfg_parses_and_plans_or_says_why_not() {
        let Some(compat) = compat() else {
            troupe_node::testing::cannot_run("../shared/compat is absent");
            return;
        };
        let golden = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden");
        let bless = std::env::var_os("TROUPE_BLESS").is_some();
        let mut files = Vec::new();
        cfgs(&compat, &mut files);
        assert!(
            files.len() >= 20,
            "expected the compat cfgs, found {}",
            files.len()
        );
        let mut failures = Vec::new();
        for f in files {
            let rel = f
                .strip_prefix(&compat)
                .unwrap()
                .to_string_lossy()
                .into_owned();
            // Every file must parse: syntax is never the reason a compat cfg fails.
            if let Err(e) = troupe_launch::cfg::parse_file(&f) {
                failures.push(format!("{rel}: does not parse: {e}"));
                continue;
            }
            let got = match plan::load(&f, troupe_msgs::DEFAULT_ROBOT, &crate::drivers::catalog()) {
                Ok((plan, warnings)) => {
                    let mut s = plan::to_toml(&plan);
                    for w in warnings {
                        s.push_str(&format!("# warning: {w}\n"));
                    }
                    s
                }
                Err(e) => format!("error:\n{e}\n"),
            };
            let got = got.replace(&compat.display().to_string(), "compat");
            let want_path = golden.join(format!("{}.txt", rel.replace('/', "__")));
            if bless {
                std::fs::create_dir_all(&golden).unwrap();
                std::fs::write(&want_path, &got).unwrap();
                continue;
            }
            match std::fs::read_to_string(&want_path) {
                Ok(want) if want == got => {}
                Ok(want) => failures.push(format!(
                    "{rel}: plan changed\n--- want\n{want}\n--- got\n{got}"
                )),
                Err(_) => failures.push(format!(
                    "{rel}: no golden file {} (run with TROUPE_BLESS=1)",
                    want_path.display()
                )),
            }
        }
        assert!(failures.is_empty(), "{}", failures.join("\n\n"));
    }
}

/// The project's own sample cfgs (worlds/) plan without error or warning.
mod sample_cfgs {
    use std::path::Path;

    use troupe_launch::plan;

    #[test]
    fn sample_cfgs_plan_cleanly() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds");
        let mut n = 0;
        for e in std::fs::read_dir(&dir).unwrap().flatten() {
            let p = e.path();
            if p.extension().is_some_and(|x| x == "cfg") {
                // With the `--external` devices its own usage comment gives.
                let text = std::fs::read_to_string(&p).unwrap();
                let external: Vec<String> = text
                    .split("--external ")
                    .skip(1)
                    .filter_map(|rest| rest.split_whitespace().next().map(str::to_owned))
                    .collect();
                let (plan, warnings) =
                    plan::load_with(&p, 6665, &external, &crate::drivers::catalog())
                        .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
                assert!(warnings.is_empty(), "{}: {warnings:?}", p.display());
                assert!(!plan.nodes.is_empty());
                n += 1;
            }
        }
        assert!(n >= 2, "worlds/ holds the sample cfgs");
    }
}

/// The repository's compose files are what this build's `troupe compose` writes.
mod compose {
    use std::path::Path;

    use troupe_fleet::docker::{render, ComposeArgs};

    /// The repository's docker-compose.yml is `troupe compose`'s output for
    /// worlds/fleet.cfg: regenerate it (the command is in its first line)
    /// when this fails.
    #[test]
    fn the_root_compose_file_is_the_generator_s_output() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let file = root.join("docker-compose.yml");
        let args = ComposeArgs {
            file: root.join("worlds/fleet.cfg"),
            robot: troupe_msgs::DEFAULT_ROBOT,
            output: Some(file.clone()),
            image: "troupe:latest".into(),
            in_image: Some("/worlds".into()),
            secure: None,
            lease: 3.0,
            swarm: false,
            k8s: false,
        };
        let want = render(&args, &crate::drivers::catalog()).unwrap();
        let have = std::fs::read_to_string(&file).unwrap();
        assert!(
            have == want,
            "docker-compose.yml drifted from `troupe compose`: run `cargo run --release -- compose worlds/fleet.cfg --in-image /worlds -o docker-compose.yml`"
        );
        assert!(want.starts_with(
            "# Written by `troupe compose worlds/fleet.cfg --in-image /worlds -o docker-compose.yml`"
        ));
        for host in [
            "router",
            "sim",
            "robot6665",
            "robot6666",
            "robot6667",
            "bridge",
        ] {
            assert!(
                want.contains(&format!("\n  {host}:\n")),
                "no service {host}"
            );
        }
    }

    #[test]
    fn a_plan_without_hosts_is_one_service_with_its_directory_mounted() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let args = ComposeArgs {
            file: root.join("worlds/simple.cfg"),
            robot: troupe_msgs::DEFAULT_ROBOT,
            output: Some(root.join("docker-compose.yml")),
            image: "troupe:latest".into(),
            in_image: None,
            secure: None,
            lease: 3.0,
            swarm: false,
            k8s: false,
        };
        let y = render(&args, &crate::drivers::catalog()).unwrap();
        assert!(y.contains("\n  stack:\n"), "{y}");
        assert!(
            y.contains(r#""launch", "/stack/simple.cfg", "--no-bridge"]"#),
            "{y}"
        );
        assert!(y.contains(r#"- "./worlds:/stack:ro""#), "{y}");
        assert!(
            y.contains(r#""127.0.0.1:${TROUPE_PORT_6665-6665}:6665""#),
            "{y}"
        );
    }

    fn fleet_args(swarm: bool, k8s: bool, in_image: Option<&str>) -> ComposeArgs {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        ComposeArgs {
            file: root.join("worlds/fleet.cfg"),
            robot: troupe_msgs::DEFAULT_ROBOT,
            output: Some(root.join("troupe-stack.yml")),
            image: "troupe:latest".into(),
            in_image: in_image.map(str::to_owned),
            secure: None,
            lease: 3.0,
            swarm,
            k8s,
        }
    }

    /// The Compose file, the Swarm stack and the Kubernetes manifests are
    /// one model of the fleet written three ways: each host runs the same
    /// command in each, and on many machines each host has a router of its
    /// own, on the host's machines, linked to the fleet's.
    #[test]
    fn the_swarm_stack_and_the_k8s_manifests_are_the_compose_file_s_services() {
        let catalog = crate::drivers::catalog();
        let compose = render(&fleet_args(false, false, Some("/worlds")), &catalog).unwrap();
        let swarm = render(&fleet_args(true, false, Some("/worlds")), &catalog).unwrap();
        let k8s = render(&fleet_args(false, true, Some("/worlds")), &catalog).unwrap();
        for host in ["sim", "robot6665", "robot6666", "robot6667"] {
            let launch =
                format!(r#""launch", "/worlds/fleet.cfg", "--host", "{host}", "--no-bridge"]"#);
            for (what, text) in [("compose", &compose), ("swarm", &swarm), ("k8s", &k8s)] {
                assert!(text.contains(&launch), "{what} runs no {host}:\n{text}");
            }
            // Beside its own router, on its own machines.
            let router = format!(r#""--connect", "tcp/router-{host}:7447", "--mode", "client""#);
            assert!(swarm.contains(&router) && k8s.contains(&router), "{host}");
            assert!(!compose.contains(&router), "one machine, one router");
            assert_eq!(
                swarm
                    .matches(&format!("node.labels.troupe.host.{host} == true"))
                    .count(),
                2,
                "{host} and its router placed by its label:\n{swarm}"
            );
            assert_eq!(
                k8s.matches(&format!("troupe.host/{host}: \"true\""))
                    .count(),
                2,
                "{host} and its router placed by its label"
            );
            assert!(k8s.contains(&format!(
                "kind: Service\nmetadata:\n  name: router-{host}\n"
            )));
        }
        assert!(swarm.contains("version: \"3.8\""));
        assert!(swarm.contains("networks:\n  fleet:\n    driver: overlay\n"));
        assert!(swarm.contains("restart_policy:\n        condition: any"));
        assert!(swarm.contains("published: ${TROUPE_PORT_6666-6666}"));
        assert_eq!(k8s.matches("kind: Deployment").count(), 10, "{k8s}");
        assert!(k8s.contains("readinessProbe:"));
        assert!(k8s.contains("port: 6667"));
    }

    #[test]
    fn a_swarm_or_a_cluster_needs_the_cfg_in_the_image() {
        let catalog = crate::drivers::catalog();
        for (swarm, k8s) in [(true, false), (false, true)] {
            let e = render(&fleet_args(swarm, k8s, None), &catalog).unwrap_err();
            assert!(e.to_string().contains("--in-image"), "{e}");
        }
    }
}
