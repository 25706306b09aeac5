//! The README and docs/ against this build: every `troupe` command they show
//! parses with today's command line, and every command in their shell
//! blocks is run by a test (named here) or says why none runs it.

use std::path::{Path, PathBuf};

use clap::Parser;

use crate::cli::Cli;

/// A command the docs show: where, and its words as the shell splits them.
#[derive(Debug)]
struct Shown {
    place: String,
    words: Vec<String>,
    in_block: bool,
}

impl Shown {
    fn line(&self) -> String {
        self.words.join(" ")
    }

    /// The arguments `troupe` gets, if this is a `troupe` command
    /// (`troupe …`, `target/release/troupe …`, `cargo run --release -- …`).
    fn troupe_args(&self) -> Option<&[String]> {
        let w = &self.words;
        match w.first()?.as_str() {
            "troupe" | "target/release/troupe" | "target/debug/troupe" => Some(&w[1..]),
            "cargo" => {
                let dashes = w.iter().position(|x| x == "--")?;
                (w.get(1)? == "run" && !w[..dashes].iter().any(|x| x == "--example"))
                    .then(|| &w[dashes + 1..])
            }
            _ => None,
        }
    }
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// README.md and every page of docs/.
fn pages() -> Vec<(String, String)> {
    let root = root();
    let mut names = vec!["README.md".to_owned()];
    let mut docs: Vec<String> = std::fs::read_dir(root.join("docs"))
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".md"))
        .map(|n| format!("docs/{n}"))
        .collect();
    docs.sort();
    names.extend(docs);
    names
        .into_iter()
        .map(|n| {
            let text = std::fs::read_to_string(root.join(&n)).unwrap();
            (n, text)
        })
        .collect()
}

/// Splits shell text into commands of words: quotes (which may span lines)
/// kept together, `#` comments dropped, `&&`, `;`, `|` and `&` ending a
/// command, a redirection's target dropped.
fn shell_commands(text: &str) -> Vec<Vec<String>> {
    let mut commands = Vec::new();
    let mut words: Vec<String> = Vec::new();
    let mut word: Option<String> = None;
    let mut redirect = false;
    let mut chars = text.chars().peekable();
    let end_word = |word: &mut Option<String>, words: &mut Vec<String>, redirect: &mut bool| {
        if let Some(w) = word.take() {
            if !std::mem::take(redirect) {
                words.push(w);
            }
        }
    };
    while let Some(c) = chars.next() {
        match c {
            '\'' | '"' => {
                let w = word.get_or_insert_with(String::new);
                for q in chars.by_ref() {
                    if q == c {
                        break;
                    }
                    w.push(q);
                }
            }
            '#' if word.is_none() => {
                while chars.peek().is_some_and(|&n| n != '\n') {
                    chars.next();
                }
            }
            ' ' | '\t' => end_word(&mut word, &mut words, &mut redirect),
            '>' => {
                end_word(&mut word, &mut words, &mut redirect);
                redirect = true;
            }
            '\n' | ';' | '&' | '|' => {
                end_word(&mut word, &mut words, &mut redirect);
                if !words.is_empty() {
                    commands.push(std::mem::take(&mut words));
                }
            }
            _ => word.get_or_insert_with(String::new).push(c),
        }
    }
    end_word(&mut word, &mut words, &mut redirect);
    if !words.is_empty() {
        commands.push(words);
    }
    commands
}

/// Every command of every page: the lines of its `sh` blocks, the `$ `
/// lines of its `console` blocks, and the inline code that starts with
/// `troupe ` and holds no placeholder (`…`, `[`, `\|`, a word in capitals).
fn shown() -> Vec<Shown> {
    let mut out = Vec::new();
    for (name, text) in pages() {
        let mut rest = text.as_str();
        let mut prose = String::new();
        while let Some(start) = rest.find("\n```") {
            prose.push_str(&rest[..start]);
            let after = &rest[start + 4..];
            let (lang, body) = after.split_once('\n').unwrap_or((after, ""));
            let end = body.find("\n```").map_or(body.len(), |e| e + 1);
            let block = &body[..end];
            let line = text[..text.len() - rest.len() + start].lines().count() + 2;
            let script = match lang.trim() {
                "sh" => block.to_owned(),
                "console" => block
                    .lines()
                    .filter_map(|l| l.strip_prefix("$ "))
                    .collect::<Vec<_>>()
                    .join("\n"),
                _ => String::new(),
            };
            for words in shell_commands(&script) {
                out.push(Shown {
                    place: format!("{name}:{line}"),
                    words,
                    in_block: true,
                });
            }
            rest = body[end..].split_once('\n').map_or("", |(_, r)| r);
        }
        prose.push_str(rest);
        for (i, span) in prose.split('`').enumerate() {
            let caps = |w: &str| w.chars().all(|c| c.is_ascii_uppercase() || c == '_');
            let placeholder = ["…", "[", "\\|"].iter().any(|p| span.contains(p))
                || span.split_whitespace().any(caps);
            if i % 2 == 1 && span.starts_with("troupe ") && !placeholder {
                for words in shell_commands(&span.replace('\n', " ")) {
                    out.push(Shown {
                        place: name.clone(),
                        words,
                        in_block: false,
                    });
                }
            }
        }
    }
    out
}

#[test]
fn the_shell_splitter_reads_the_docs_forms() {
    let got = shell_commands(
        "troupe a 'b c' # note\nprintf 'x\ny' > f && troupe b &\ncargo build | tail\n",
    );
    let want: Vec<Vec<&str>> = vec![
        vec!["troupe", "a", "b c"],
        vec!["printf", "x\ny"],
        vec!["troupe", "b"],
        vec!["cargo", "build"],
        vec!["tail"],
    ];
    assert_eq!(got, want);
}

/// The examples of every command's `--help`: its lines that run `troupe`.
fn help_examples(cmd: &clap::Command, path: &str, out: &mut Vec<Shown>) {
    let help = cmd
        .get_after_help()
        .map(|h| h.to_string())
        .unwrap_or_default();
    for line in help.lines() {
        let line = line.trim_start().trim_start_matches("$ ");
        if line.starts_with("troupe ") || line.starts_with("cargo run --release -- ") {
            for words in shell_commands(line) {
                out.push(Shown {
                    place: format!("`{path} --help`"),
                    words,
                    in_block: false,
                });
            }
        }
    }
    for sub in cmd.get_subcommands() {
        help_examples(sub, &format!("{path} {}", sub.get_name()), out);
    }
}

#[test]
fn every_troupe_command_the_docs_and_the_help_show_parses() {
    let mut shown = shown();
    help_examples(
        &<Cli as clap::CommandFactory>::command(),
        "troupe",
        &mut shown,
    );
    let commands: Vec<&Shown> = shown.iter().filter(|s| s.troupe_args().is_some()).collect();
    assert!(
        commands.len() > 150,
        "only {} commands found",
        commands.len()
    );
    let mut failures = Vec::new();
    for s in commands {
        let mut argv = vec!["troupe".to_owned()];
        argv.extend(s.troupe_args().unwrap().iter().cloned());
        if let Err(e) = Cli::try_parse_from(&argv) {
            use clap::error::ErrorKind::{DisplayHelp, DisplayVersion, MissingRequiredArgument};
            // Inline code may name a command without its arguments
            // (`troupe map build`); what it does give must parse.
            let named = !s.in_block && e.kind() == MissingRequiredArgument;
            if !named && !matches!(e.kind(), DisplayHelp | DisplayVersion) {
                failures.push(format!("{}: `{}`:\n{e}", s.place, s.line()));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Who runs each command of the docs' shell blocks: a test (by the name of
/// its function, which must exist), or the reason none does. The first
/// entry whose words begin the command's words decides.
const RUN_BY: &[(&str, &str)] = &[
    // docs/ros2.md: ROS 2's own tools are not installed here; the test's
    // ROS 2 peer (hiroz) does what each does.
    (
        "troupe launch worlds/nav.cfg --ros2",
        "a_ros2_peer_sees_drives_and_maps_a_troupe_robot",
    ),
    (
        "ros2",
        "no ROS 2 install here: a_ros2_peer_sees_drives_and_maps_a_troupe_robot lists the graph, echoes the scan, drives by cmd_vel and calls GetMap as a ROS 2 peer",
    ),
    (
        "rviz2",
        "no ROS 2 install here: a_ros2_peer_sees_drives_and_maps_a_troupe_robot subscribes to the map late and transient-local, as rviz2's Map display does",
    ),
    // README: the two commands, and the first ten minutes.
    ("cargo test", "CI: .ci/run is this command"),
    ("cargo build --release", "CI: .ci/run builds the workspace"),
    ("export", "the_first_ten_minutes_run_as_printed"),
    ("troupe list", "the_first_ten_minutes_run_as_printed"),
    (
        "troupe echo laser:0",
        "the_first_ten_minutes_run_as_printed",
    ),
    (
        "troupe hz position2d:0",
        "the_first_ten_minutes_run_as_printed",
    ),
    (
        "troupe cmd position2d:0",
        "the_first_ten_minutes_run_as_printed",
    ),
    (
        "troupe call simulation:0",
        "the_first_ten_minutes_run_as_printed",
    ),
    (
        "troupe record -o run.mcap --duration 5",
        "the_first_ten_minutes_run_as_printed",
    ),
    (
        "troupe log info run.mcap",
        "the_first_ten_minutes_run_as_printed",
    ),
    ("troupe view", "the_first_ten_minutes_run_as_printed"),
    (
        "pip install ./python",
        "the_python_package_passes_its_tests_and_lessons",
    ),
    (
        "python3 examples/python/wander.py",
        "the_python_package_passes_its_tests_and_lessons",
    ),
    (
        "python examples/python/gripper.py",
        "the_python_package_passes_its_tests_and_lessons",
    ),
    // The tutorial and the CLI page.
    (
        "cargo run --release -- launch worlds/simple.cfg",
        "the_first_ten_minutes_run_as_printed",
    ),
    (
        "troupe launch worlds/simple.cfg",
        "a_recorded_stage_run_plays_back_in_order_ten_times_faster",
    ),
    (
        "cargo run --release -- launch worlds/gripper.cfg",
        "gripper_drags_the_box_back",
    ),
    (
        "cargo run --release --example",
        "every lesson: examples/tests run each against its stack",
    ),
    (
        "cargo test -p troupe-examples",
        "every lesson: examples/tests run each against its stack",
    ),
    (
        "troupe echo position2d:0",
        "the_first_ten_minutes_run_as_printed",
    ),
    (
        "troupe hz laser:0",
        "cmd_drives_the_base_and_stops_it_and_call_asks_and_explains_refusals",
    ),
    (
        "playerprint",
        "none: a Player client to try by hand; the bridge tests speak its protocol",
    ),
    (
        "playerv",
        "none: a GUI; the bridge tests speak its protocol",
    ),
    // Hardware.
    ("troupe emulate", "the_hardware_recipe_runs_as_printed"),
    ("printf", "the_hardware_recipe_runs_as_printed"),
    (
        "troupe launch hw.cfg",
        "the_hardware_recipe_runs_as_printed",
    ),
    // Fleets.
    ("docker-compose", DOCKER_FLEET),
    // docs/fleets.md, many machines.
    (
        "troupe compose worlds/fleet.cfg --in-image /worlds --swarm",
        SWARM,
    ),
    ("docker node update", SWARM),
    ("docker stack deploy", SWARM),
    ("docker stack rm", SWARM),
    (
        "troupe compose worlds/fleet.cfg --in-image /worlds --k8s",
        K8S,
    ),
    (
        "kubectl",
        "no cluster here: k8s_manifests_validate_against_kubernetes_own_schemas checks the manifests against Kubernetes' own schemas",
    ),
    ("target/release/troupe image", DOCKER_FLEET),
    ("cargo run --release -- list", DOCKER_FLEET),
    (
        "troupe fleet-keys",
        "the_secured_fleet_of_the_docs_runs_on_one_machine",
    ),
    (
        "troupe --zenoh-config",
        "the_secured_fleet_of_the_docs_runs_on_one_machine",
    ),
    // Logs and maps.
    (
        "troupe launch worlds/record.cfg",
        "a_recorded_run_localizes_offline_as_it_did_live",
    ),
    (
        "troupe launch worlds/replay.cfg",
        "a_recorded_run_localizes_offline_as_it_did_live",
    ),
    (
        "troupe echo localize:0",
        "a_recorded_run_localizes_offline_as_it_did_live",
    ),
    (
        "troupe launch worlds/slam.cfg",
        "troupe_map_save_writes_the_live_slam_map",
    ),
    (
        "troupe launch worlds/log-slam.cfg",
        "a_log_with_odometry_error_maps_and_the_builder_finds_the_error",
    ),
    (
        "troupe map build r0.log -o room.yaml",
        "a_log_with_odometry_error_maps_and_the_builder_finds_the_error",
    ),
    ("troupe map save", "troupe_map_save_writes_the_live_slam_map"),
    (
        "troupe map",
        "a_recorded_run_localizes_offline_as_it_did_live",
    ),
    (
        "troupe foxglove",
        "test_foxglove_shows_the_fleet_and_its_teleop_drives_a_robot",
    ),
    (
        "troupe launch worlds/nav.cfg --foxglove",
        "test_foxglove_shows_the_fleet_and_its_teleop_drives_a_robot",
    ),
    (
        "troupe record --format foxglove",
        "test_a_recording_reads_as_foxglove_in_the_ecosystem_s_reader",
    ),
    (
        "troupe log export run.mcap --format foxglove",
        "test_a_recording_reads_as_foxglove_in_the_ecosystem_s_reader",
    ),
    (
        "troupe record --rosbag2",
        "test_a_recording_reads_as_ros2_in_the_ecosystem_s_reader",
    ),
    (
        "troupe log export run.mcap --rosbag2",
        "test_a_recording_reads_as_ros2_in_the_ecosystem_s_reader",
    ),
    (
        "troupe record --format ros2",
        "test_a_recording_reads_as_ros2_in_the_ecosystem_s_reader",
    ),
    (
        "troupe log export run.mcap --format ros2",
        "test_a_recording_reads_as_ros2_in_the_ecosystem_s_reader",
    ),
    (
        "troupe play ros.mcap",
        "test_a_ros2_bag_written_by_ros_tools_plays_into_amcl",
    ),
    (
        "troupe launch worlds/nav.cfg",
        "test_a_recording_reads_as_ros2_in_the_ecosystem_s_reader",
    ),
    (
        "troupe record",
        "a_recorded_stage_run_plays_back_in_order_ten_times_faster",
    ),
    (
        "troupe --namespace replay play",
        "a_recorded_stage_run_plays_back_in_order_ten_times_faster",
    ),
    (
        "troupe log export",
        "a_recorded_stage_run_plays_back_in_order_ten_times_faster",
    ),
];

const DOCKER_FLEET: &str =
    "docker_fleet_comes_up_drives_a_robot_from_a_player_client_and_goes_down_cleanly";

/// The test that deploys the Swarm stack on a one-node swarm.
const SWARM: &str =
    "docker_swarm_runs_the_generated_stack_reschedules_a_killed_host_and_heals_a_cut_router";

/// The test that checks the Kubernetes manifests against Kubernetes' schemas.
const K8S: &str = "k8s_manifests_validate_against_kubernetes_own_schemas";

/// The source files whose test functions `RUN_BY` may name.
fn test_sources(dir: &Path, out: &mut String) {
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        let name = e.file_name();
        if p.is_dir() && name != "target" && name != "fuzz" {
            test_sources(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs" || x == "py") {
            out.push_str(&std::fs::read_to_string(&p).unwrap_or_default());
        }
    }
}

#[test]
fn every_command_of_the_docs_shell_blocks_is_run_by_a_test() {
    let root = root();
    let mut sources = String::new();
    for dir in ["tests", "examples", "python", "cli", ".ci"] {
        test_sources(&root.join(dir), &mut sources);
    }
    let mut failures = Vec::new();
    for s in shown().iter().filter(|s| s.in_block) {
        let line = s.line();
        let Some((_, by)) = RUN_BY.iter().find(|(prefix, _)| {
            let p: Vec<&str> = prefix.split(' ').collect();
            s.words.len() >= p.len() && s.words.iter().zip(&p).all(|(w, p)| w == p)
        }) else {
            failures.push(format!(
                "{}: `{line}`: no test runs it (add it to RUN_BY)",
                s.place
            ));
            continue;
        };
        let named_test = !by.contains(' ');
        // A Rust test, or a Python one (pytest's `def test_…(`).
        let defined = [format!("fn {by}("), format!("def {by}(")];
        if named_test && !defined.iter().any(|d| sources.contains(d.as_str())) {
            failures.push(format!("{}: `{line}`: test `{by}` does not exist", s.place));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The local targets of a page's Markdown links and images (`](path)`):
/// not web addresses, not anchors within the page; an anchor after a path
/// dropped.
fn local_links(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = text;
    while let Some(at) = rest.find("](") {
        rest = &rest[at + 2..];
        let Some(end) = rest.find(')') else { break };
        let target = rest[..end].split_whitespace().next().unwrap_or("");
        let path = target.split('#').next().unwrap_or("");
        if !path.is_empty() && !path.contains("://") && !path.starts_with("mailto:") {
            out.push(path.to_owned());
        }
    }
    out
}

#[test]
fn every_image_and_local_link_of_the_docs_exists() {
    let root = root();
    let mut pages = pages();
    pages.push((
        "ARCHITECTURE.md".into(),
        std::fs::read_to_string(root.join("ARCHITECTURE.md")).unwrap(),
    ));
    let mut broken = Vec::new();
    for (name, text) in &pages {
        let dir = root.join(name).parent().unwrap().to_path_buf();
        for link in local_links(text) {
            if !dir.join(&link).exists() {
                broken.push(format!("{name}: {link}"));
            }
        }
    }
    assert!(
        broken.is_empty(),
        "links to nothing:\n{}",
        broken.join("\n")
    );
    assert_eq!(
        local_links("![a](x.png) [b](https://e.org) [c](#top) [d](y.md#s \"t\")"),
        ["x.png", "y.md"]
    );
}
