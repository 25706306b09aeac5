//! The README's and docs' command lines, run as printed, but for what a
//! test must change: its own router port and namespace (`--connect`,
//! `--namespace`), a fresh directory for the files they write, and a free
//! port for the view. (The cli crate checks that every command the docs
//! show parses, and names the test that runs each.)

use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use troupe_tests::{strings, Proc};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The first code block of `lang` after `heading` in `page`.
pub(crate) fn block(page: &str, heading: &str, lang: &str) -> String {
    let text = std::fs::read_to_string(root().join(page)).unwrap();
    let section = &text[text
        .find(heading)
        .unwrap_or_else(|| panic!("{page}: {heading}"))..];
    let open = format!("```{lang}\n");
    let body = &section[section.find(&open).expect("the block") + open.len()..];
    body[..body.find("```").expect("its end")].to_owned()
}

/// A console block's commands, each with the lines printed after it.
fn console(block: &str) -> Vec<(Vec<String>, Vec<String>)> {
    let mut out: Vec<(Vec<String>, Vec<String>)> = Vec::new();
    for line in block.lines() {
        if let Some(cmd) = line.strip_prefix("$ ") {
            let cmd = cmd.split("  #").next().unwrap_or("");
            out.push((strings(&cmd.split_whitespace().collect::<Vec<_>>()), vec![]));
        } else if let Some(last) = out.last_mut() {
            last.1.push(line.to_owned());
        }
    }
    out
}

/// The words of each line, for comparing tables whatever their spacing.
fn rows(lines: &[String]) -> Vec<Vec<String>> {
    let mut v: Vec<Vec<String>> = lines
        .iter()
        .map(|l| l.split_whitespace().map(str::to_owned).collect())
        .filter(|w: &Vec<String>| !w.is_empty())
        .collect();
    v.sort();
    v
}

/// r0's position from `troupe call simulation:0 get_pose2d r0`'s answer.
fn position(answer: &str) -> (f64, f64) {
    let field = |name: &str| -> f64 {
        let at = answer
            .find(&format!("\"{name}\":"))
            .unwrap_or_else(|| panic!("{answer}"));
        let rest = &answer[at + name.len() + 3..];
        let end = rest.find([',', '}']).unwrap_or(rest.len());
        rest[..end].parse().unwrap_or_else(|_| panic!("{answer}"))
    };
    (field("x"), field("y"))
}

#[test]
fn the_first_ten_minutes_run_as_printed() {
    // The first of the two commands, as a test launches it.
    let two = block("README.md", "## The two commands", "sh");
    let first = two.lines().next().unwrap().split("  #").next().unwrap();
    let cfg = first
        .strip_prefix("cargo run --release -- launch ")
        .expect("the first command launches a cfg")
        .trim();
    let ns = troupe_tests::unique_namespace("docs");
    let mut launcher = troupe_tests::launch(&ns, &root().join(cfg), &[]);
    let (router, _) = troupe_tests::launch_ports(&mut launcher);
    let session = troupe_tests::client_at(&router, &ns);
    troupe_tests::wait_live(&session, &["6665:laser:0", "6665:position2d:0"]);
    let dir = std::env::temp_dir().join(troupe_tests::unique_namespace("ten-minutes"));
    std::fs::create_dir_all(&dir).unwrap();
    let net = strings(&["--connect", &router, "--namespace", &ns, "--no-multicast"]);
    let run = |args: &[String]| {
        let mut all = net.clone();
        all.extend(args.iter().cloned());
        let mut cmd = std::process::Command::new(troupe_tests::troupe_bin());
        cmd.args(&all).current_dir(&dir);
        let (status, out, err) = Proc::start("troupe", &mut cmd).output();
        assert!(status.success(), "troupe {}: {out}{err}", args.join(" "));
        out
    };
    let start = position(&run(&strings(&[
        "call",
        "simulation:0",
        "get_pose2d",
        "r0",
    ])));

    let steps = console(&block("README.md", "## The first ten minutes", "console"));
    let names: Vec<&str> = steps.iter().map(|(c, _)| c[1].as_str()).collect();
    assert_eq!(
        names,
        [
            "PATH=$PWD/target/release:$PATH",
            "list",
            "echo",
            "hz",
            "cmd",
            "call",
            "record",
            "log",
            "view"
        ],
        "the test knows these steps; teach it a new one"
    );
    for (cmd, printed) in &steps {
        let args = &cmd[1..];
        match args[0].as_str() {
            // The binary the first command builds is the one these name.
            p if cmd[0] == "export" => assert!(p.contains("target/release"), "{p}"),
            "list" => {
                let out = run(args);
                let got: Vec<String> = out.lines().map(str::to_owned).collect();
                assert_eq!(rows(&got), rows(printed), "{out}");
            }
            "echo" => {
                let out = run(args);
                let head = |s: &str| s.split("  t=").next().unwrap_or("").to_owned();
                assert_eq!(head(&out), head(&printed[0]), "{out}");
                assert!(out.contains(" LaserScan {\"id\":0,"), "{out}");
            }
            "hz" => {
                let out = run(args);
                let kind = printed[0].rsplit(' ').next().unwrap();
                assert!(
                    out.lines()
                        .any(|l| l.starts_with("rate: ") && l.ends_with(kind)),
                    "{out}"
                );
            }
            "cmd" => {
                run(args);
            }
            "call" => {
                let (x, y) = position(&run(args));
                let moved = (x - start.0).hypot(y - start.1);
                assert!(moved > 0.3, "r0 moved {moved} m from {start:?}");
            }
            "record" => {
                let out = run(args);
                assert!(out.contains("0 dropped"), "{out}");
            }
            "log" => {
                let out = run(args);
                assert!(out.contains("robot/6665/laser/0"), "{out}");
            }
            "view" => {
                let mut all = net.clone();
                all.extend(args.iter().cloned());
                all.extend(strings(&["--port", "0"]));
                let mut view = Proc::troupe("view", &all);
                let line = view.first_line();
                let addr = line
                    .split("http://")
                    .nth(1)
                    .and_then(|a| a.split('/').next())
                    .unwrap_or_else(|| panic!("no address in {line:?}"))
                    .to_owned();
                let mut tcp = std::net::TcpStream::connect(&addr).unwrap();
                write!(tcp, "GET / HTTP/1.0\r\nHost: {addr}\r\n\r\n").unwrap();
                let mut answer = String::new();
                tcp.read_to_string(&mut answer).unwrap();
                assert!(answer.starts_with("HTTP/1.0 200 OK"), "{answer}");
                assert!(answer.contains("<canvas"), "not the page: {answer}");
                assert!(view.terminate().success(), "{}", view.stderr());
            }
            other => panic!("a step the test does not know: {other}"),
        }
    }
    assert!(launcher.terminate().success(), "{}", launcher.stderr());
    let _ = std::fs::remove_dir_all(&dir);
}

/// docs/drivers.md's hardware recipe: two emulators, the cfg its `printf`
/// writes, and a launch of it, in a fresh directory instead of /tmp.
#[test]
fn the_hardware_recipe_runs_as_printed() {
    let dir = std::env::temp_dir().join(troupe_tests::unique_namespace("hardware"));
    std::fs::create_dir_all(&dir).unwrap();
    let here = format!("{}/", dir.display());
    let text =
        block("docs/drivers.md", "## Hardware, real or emulated", "sh").replace("/tmp/", &here);
    let mut emulators = Vec::new();
    let mut launched = None;
    for line in text
        .split("\ntroupe ")
        .map(|l| l.trim_start_matches("troupe "))
    {
        // `troupe emulate …` may be followed by the printf of the cfg.
        let line = match line.split_once("\nprintf '") {
            Some((command, printf)) => {
                let (body, target) = printf.split_once("' > ").expect("printf 'TEXT' > FILE");
                std::fs::write(dir.join(target.trim()), body.replace("\\n", "")).unwrap();
                command
            }
            None => line,
        };
        let (line, _) = line.split_once("  #").unwrap_or((line, ""));
        if line.starts_with("emulate ") {
            emulators.push(line.to_owned());
        } else if let Some(cfg) = line.strip_prefix("launch ") {
            launched = Some(cfg.trim().to_owned());
        }
    }
    assert_eq!(emulators.len(), 2, "{text}");
    let _emulators: Vec<Proc> = emulators
        .iter()
        .map(|l| {
            let words: Vec<&str> = l.trim().trim_end_matches('&').split_whitespace().collect();
            let mut p = Proc::troupe("emulate", &strings(&words));
            let line = p.first_line();
            assert!(line.starts_with("troupe emulate: "), "{line:?}");
            p
        })
        .collect();
    let cfg = dir.join(launched.expect("a launch line"));
    let ns = troupe_tests::unique_namespace("hardware");
    let mut launcher = troupe_tests::launch(&ns, &cfg, &["--no-bridge"]);
    let router = launcher.endpoint("troupe launch: router listening on");
    let session = troupe_tests::client_at(&router, &ns);
    troupe_tests::wait_live(
        &session,
        &["6665:position2d:0", "6665:sonar:0", "6665:laser:0"],
    );
    assert!(launcher.terminate().success(), "{}", launcher.stderr());
    let _ = std::fs::remove_dir_all(&dir);
}
