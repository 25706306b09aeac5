//! `troupe bench launch`: from `troupe launch` to every device live, and
//! back after a node is killed, for a 5-node plan.

use std::io::Write;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Args;
use troupe_msgs::keys;
use troupe_node::zenoh::Wait;
use troupe_node::{Mode, ZenohArgs};

/// Flags of `troupe bench launch`.
#[derive(Debug, Args)]
pub struct LaunchBenchArgs {
    /// Launches to time.
    #[arg(long, default_value_t = 5)]
    pub runs: usize,
}

/// The 5-node plan `bench launch` times: two ranger→laser pipelines and a base.
const FIVE_NODES: &str = "\
driver ( name \"dummy\" provides [\"ranger:0\"] rate 10 )
driver ( name \"rangertolaser\" requires [\"ranger:0\"] provides [\"laser:0\"] )
driver ( name \"dummy\" provides [\"ranger:1\"] rate 10 )
driver ( name \"rangertolaser\" requires [\"ranger:1\"] provides [\"laser:1\"] )
driver ( name \"dummy\" provides [\"position2d:0\"] rate 10 )
";

/// Child processes of `parent` that run `troupe node`, with their cmdline.
fn node_children(parent: u32) -> Vec<(u32, String)> {
    let mut out = Vec::new();
    let Ok(dir) = std::fs::read_dir("/proc") else {
        return out;
    };
    for e in dir.flatten() {
        let Ok(pid) = e.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let Ok(stat) = std::fs::read_to_string(format!("/proc/{pid}/stat")) else {
            continue;
        };
        let Some((_, rest)) = stat.rsplit_once(") ") else {
            continue;
        };
        let mut f = rest.split(' ');
        let (state, ppid) = (f.next(), f.next().and_then(|p| p.parse::<u32>().ok()));
        let cmd = std::fs::read_to_string(format!("/proc/{pid}/cmdline")).unwrap_or_default();
        if ppid == Some(parent) && state != Some("Z") && cmd.contains("\0node\0") {
            out.push((pid, cmd.replace('\0', " ")));
        }
    }
    out
}

fn median(v: &mut [Duration]) -> Duration {
    v.sort();
    v.get(v.len() / 2).copied().unwrap_or_default()
}

fn ms(d: Duration) -> String {
    format!("{:.0} ms", d.as_secs_f64() * 1e3)
}

/// `troupe bench launch`: launch-to-live and kill-to-live times of a 5-node plan.
pub fn run(a: &LaunchBenchArgs) -> anyhow::Result<()> {
    use std::io::BufRead;
    use troupe_node::zenoh::sample::SampleKind;
    let dir = std::env::temp_dir().join(format!("troupe-bench-launch-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let cfg = dir.join("five.cfg");
    std::fs::write(&cfg, FIVE_NODES)?;
    let exe = std::env::current_exe()?;
    let (mut ups, mut restarts, mut stops) = (Vec::new(), Vec::new(), Vec::new());
    for run in 0..a.runs.max(1) {
        let ns = format!("bench-launch-{}-{run}", std::process::id());
        let t0 = Instant::now();
        let mut child = Command::new(&exe)
            .args(["--namespace", &ns, "launch"])
            .arg(&cfg)
            .args(["--listen", "tcp/127.0.0.1:0", "--bridge-any-port"])
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()?;
        let result = (|| -> anyhow::Result<()> {
            let out = child.stdout.take().context("launcher stdout")?;
            let mut line = String::new();
            std::io::BufReader::new(out).read_line(&mut line)?;
            let endpoint = line
                .trim()
                .strip_prefix("troupe launch: router listening on ")
                .and_then(|l| l.split(' ').next())
                .with_context(|| format!("unexpected launcher output {line:?}"))?
                .to_owned();
            let probe = ZenohArgs {
                connect: vec![endpoint],
                namespace: Some(ns.clone()),
                no_multicast: true,
                ..Default::default()
            }
            .open(Mode::Client)?;
            let tokens = probe
                .liveliness()
                .declare_subscriber(keys::tokens(None))
                .history(true)
                .wait()
                .map_err(|e| anyhow::anyhow!("{e}"))?;
            let deadline = Instant::now() + Duration::from_secs(30);
            let mut live = std::collections::BTreeSet::new();
            while live.len() < 5 {
                let t = tokens
                    .recv_deadline(deadline)
                    .map_err(|e| anyhow::anyhow!("{e}"))?
                    .context("the 5 devices did not come up within 30 s")?;
                if t.kind() == SampleKind::Put {
                    live.insert(t.key_expr().to_string());
                }
            }
            ups.push(t0.elapsed());
            // Kill one node (a different one each run) and time its device's return.
            let kids = node_children(child.id());
            let (pid, cmd) = kids
                .get(run % kids.len().max(1))
                .cloned()
                .context("no node children")?;
            let token = live
                .iter()
                .find(|k| {
                    keys::parse_token(k).is_ok_and(|(d, _)| cmd.contains(&format!("\"{}\"", d)))
                })
                .cloned()
                .with_context(|| format!("which device does `{cmd}` serve?"))?;
            let t1 = Instant::now();
            let p = nix::unistd::Pid::from_raw(i32::try_from(pid)?);
            nix::sys::signal::kill(p, nix::sys::signal::Signal::SIGKILL)?;
            let mut dropped = false;
            loop {
                let t = tokens
                    .recv_deadline(deadline)
                    .map_err(|e| anyhow::anyhow!("{e}"))?
                    .context("the killed node did not come back within 30 s")?;
                if t.key_expr().as_str() == token {
                    match t.kind() {
                        SampleKind::Delete => dropped = true,
                        SampleKind::Put if dropped => break,
                        SampleKind::Put => {}
                    }
                }
            }
            restarts.push(t1.elapsed());
            Ok(())
        })();
        let t2 = Instant::now();
        if let Ok(p) = i32::try_from(child.id()) {
            let _ = nix::sys::signal::kill(
                nix::unistd::Pid::from_raw(p),
                nix::sys::signal::Signal::SIGTERM,
            );
        }
        let status = child.wait()?;
        stops.push(t2.elapsed());
        result?;
        if !status.success() {
            anyhow::bail!("the launcher did not stop cleanly: {status}");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "troupe bench launch: 5-node plan (3 dummy + 2 rangertolaser), {} runs, embedded router",
        ups.len()
    )?;
    let list = |v: &[Duration]| v.iter().map(|d| ms(*d)).collect::<Vec<_>>().join(" ");
    writeln!(
        out,
        "  launch → all 5 devices live   median {:>7}   ({})",
        ms(median(&mut ups.clone())),
        list(&ups)
    )?;
    writeln!(
        out,
        "  SIGKILL a node → device back  median {:>7}   ({})",
        ms(median(&mut restarts.clone())),
        list(&restarts)
    )?;
    writeln!(
        out,
        "  SIGTERM → launcher exited     median {:>7}   ({})",
        ms(median(&mut stops.clone())),
        list(&stops)
    )?;
    Ok(())
}
