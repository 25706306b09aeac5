//! `troupe bench stage --stage BIN`: a world run by Stage itself and by
//! Troupe, whole processes taking turns, so that both figures come from
//! the same hour of a machine whose speed drifts by ±20% from one hour to
//! the next (docs/measured.md), and their ratio is printed in one run.

use std::ffi::{OsStr, OsString};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

use anyhow::Context;
use nix::sys::resource::{getrusage, UsageWho};

/// One run of a whole process: wall seconds, CPU seconds, peak memory (MB),
/// and what it wrote to stdout.
struct Run {
    wall: f64,
    cpu: f64,
    peak_mb: f64,
    stdout: String,
}

/// `troupe bench measure -- CMD…`: runs CMD as this process's only child,
/// passes its stdout on, then prints `measured WALL CPU PEAK_KB`: the
/// child's own figures, as `getrusage(RUSAGE_CHILDREN)` gives them only
/// to a parent of one child (peak memory included, which no other way
/// reads without `unsafe` code). Fails as CMD fails, with its stderr.
pub fn measure(cmd: &[OsString]) -> anyhow::Result<()> {
    let (prog, args) = cmd.split_first().context("no command to measure")?;
    let t0 = Instant::now();
    let out = Command::new(prog)
        .args(args)
        .stdin(Stdio::null())
        .stderr(Stdio::inherit())
        .output()
        .with_context(|| format!("cannot start {}", prog.to_string_lossy()))?;
    let wall = t0.elapsed().as_secs_f64();
    let used = getrusage(UsageWho::RUSAGE_CHILDREN)?;
    let secs = |t: nix::sys::time::TimeVal| t.tv_sec() as f64 + t.tv_usec() as f64 * 1e-6;
    let mut stdout = std::io::stdout().lock();
    stdout.write_all(&out.stdout)?;
    anyhow::ensure!(
        out.status.success(),
        "{} {}: {}",
        prog.to_string_lossy(),
        args.iter()
            .map(|a| a.to_string_lossy())
            .collect::<Vec<_>>()
            .join(" "),
        out.status
    );
    writeln!(
        stdout,
        "measured {wall:.4} {:.4} {}",
        secs(used.user_time()) + secs(used.system_time()),
        used.max_rss()
    )?;
    Ok(())
}

/// Runs `cmd` under `troupe bench measure`.
fn measured(me: &Path, cmd: &[&OsStr], what: &str) -> anyhow::Result<Run> {
    let out = Command::new(me)
        .args(["bench", "measure", "--"])
        .args(cmd)
        .stdin(Stdio::null())
        .output()
        .with_context(|| format!("cannot run {what}"))?;
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr);
    let lines: Vec<&str> = stderr.lines().collect();
    let tail = &lines[lines.len().saturating_sub(8)..];
    anyhow::ensure!(
        out.status.success(),
        "{what} failed ({}); its last words:\n{}",
        out.status,
        tail.join("\n")
    );
    let figures = stdout
        .lines()
        .rev()
        .find_map(|l| l.strip_prefix("measured "))
        .with_context(|| format!("{what}: no figures in {stdout:?}"))?;
    let nums: Vec<f64> = figures
        .split_whitespace()
        .filter_map(|v| v.parse().ok())
        .collect();
    let [wall, cpu, peak_kb] = nums[..] else {
        anyhow::bail!("{what}: cannot read {figures:?}");
    };
    Ok(Run {
        wall,
        cpu,
        peak_mb: peak_kb / 1024.0,
        stdout,
    })
}

/// Stage's world `text` set up to run as `troupe bench stage` runs it: flat
/// out (`speedup -1`), unpaused, `threads` threads, stopping after
/// `seconds` simulated seconds (`quit_time`). Those top-level settings the
/// file had are dropped, and ours come first; a setting inside a model's
/// parentheses is left alone.
pub(crate) fn staged(text: &str, threads: usize, seconds: f64) -> String {
    const OURS: [&str; 4] = ["speedup", "paused", "threads", "quit_time"];
    let mut out = format!(
        "# troupe bench stage: flat out, unpaused, {seconds} simulated s, {threads} thread(s)\n\
         speedup -1\npaused 0\nthreads {threads}\nquit_time {seconds}\n"
    );
    let mut depth = 0i32;
    for line in text.lines() {
        let code = code_of(line);
        let first = code.split_whitespace().next().unwrap_or("");
        if !(depth == 0 && OURS.contains(&first)) {
            out.push_str(line);
            out.push('\n');
        }
        depth += code.matches('(').count() as i32 - code.matches(')').count() as i32;
    }
    out
}

/// Where `line`'s comment starts: its first `#` outside quotes.
fn comment_at(line: &str) -> Option<usize> {
    let mut quoted = false;
    line.char_indices().find_map(|(i, c)| match c {
        '"' => {
            quoted = !quoted;
            None
        }
        '#' if !quoted => Some(i),
        _ => None,
    })
}

/// `line` without its comment and its quoted strings (whose `#` and
/// parentheses are text).
fn code_of(line: &str) -> String {
    let code = &line[..comment_at(line).unwrap_or(line.len())];
    // Quoted strings are the odd pieces between quotes.
    code.split('"').step_by(2).collect()
}

/// Stage's benchmark/cave.world with every robot's controller Stage's
/// `wander` instead of `expand_pioneer`: `wander` reads the laser every
/// step (180 rays a robot), where `expand_pioneer` reads only the sonars.
/// The copy is written beside the original, whose includes it shares, and
/// removed when this is dropped.
pub struct WanderCave(Staged);

impl WanderCave {
    /// The row's name and what it says the world is.
    pub const LABEL: (&'static str, &'static str) = (
        "cave+wander",
        "Stage's benchmark/cave.world with ctrl \"wander\" for \"expand_pioneer\": every robot reads its 180-beam laser every step",
    );

    /// Writes the copy of `cave` (Stage's benchmark/cave.world).
    pub fn write(cave: &Path) -> anyhow::Result<WanderCave> {
        let copy = Staged::beside(cave, "cave-wander.world", |text| {
            wandering(text).with_context(|| {
                format!(
                    "{}: no `ctrl \"expand_pioneer\"` to swap for `wander`",
                    cave.display()
                )
            })
        })?;
        Ok(WanderCave(copy))
    }

    /// Where the copy is.
    pub fn path(&self) -> &Path {
        &self.0 .0
    }
}

/// `text` with each `ctrl "expand_pioneer"` outside comments turned into
/// `ctrl "wander"`; `None` when there is none.
fn wandering(text: &str) -> Option<String> {
    let mut swapped = 0;
    let mut out = String::with_capacity(text.len());
    for line in text.lines() {
        let (code, comment) = line.split_at(comment_at(line).unwrap_or(line.len()));
        let turned = code.replace("ctrl \"expand_pioneer\"", "ctrl \"wander\"");
        swapped += usize::from(turned != code);
        out.push_str(&turned);
        out.push_str(comment);
        out.push('\n');
    }
    (swapped > 0).then_some(out)
}

/// The hidden flags that give `troupe bench stage --world` a row's name
/// and what it says the world is (none without a label).
pub(crate) fn label_args<'a>(label: Option<(&'a str, &'a str)>) -> Vec<&'a OsStr> {
    label.map_or_else(Vec::new, |(name, what)| {
        vec![OsStr::new("--label"), OsStr::new(name), OsStr::new(what)]
    })
}

/// Removes the staged copy of a world, however the comparison ends.
struct Staged(PathBuf);

impl Staged {
    /// Writes `edit` of `world`'s text beside it (its includes and bitmaps
    /// resolve from there), as `.troupe-bench-PID-name`.
    fn beside(
        world: &Path,
        name: &str,
        edit: impl FnOnce(&str) -> anyhow::Result<String>,
    ) -> anyhow::Result<Staged> {
        let text = std::fs::read_to_string(world)
            .with_context(|| format!("cannot read {}", world.display()))?;
        let copy = world.with_file_name(format!(".troupe-bench-{}-{name}", std::process::id()));
        std::fs::write(&copy, edit(&text)?)
            .with_context(|| format!("cannot write the copy {}", copy.display()))?;
        Ok(Staged(copy))
    }
}

impl Drop for Staged {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// The median of `v` (the mean of the middle two when even).
fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => v[n / 2],
        n => (v[n / 2 - 1] + v[n / 2]) / 2.0,
    }
}

/// How long, on how many threads, and how many times each side runs.
pub struct Runs {
    /// Simulated seconds of each run.
    pub seconds: f64,
    /// Troupe's worker threads (Stage's `threads`).
    pub threads: usize,
    /// Runs of each side, in turn.
    pub pairs: u32,
}

/// Runs `world` with Stage (`stage -g`, from a copy set up by [`staged`]
/// beside it, so that its includes and bitmaps resolve) and with Troupe,
/// `a.pairs` times each in turn, and prints Troupe's row and both sides'
/// medians with their ratio.
pub fn compare(
    a: &Runs,
    stage: &Path,
    world: &Path,
    label: Option<(&str, &str)>,
) -> anyhow::Result<()> {
    let file_name = world
        .file_name()
        .context("a world file, not a directory")?
        .to_string_lossy()
        .into_owned();
    let name = label.map_or_else(|| file_name.clone(), |(name, _)| name.to_owned());
    let copy = Staged::beside(world, &file_name, |text| {
        Ok(staged(text, a.threads, a.seconds))
    })?;
    let me = std::env::current_exe()?;
    let (seconds, threads) = (a.seconds.to_string(), a.threads.to_string());
    let flags = [
        "bench",
        "stage",
        "--seconds",
        &seconds,
        "--threads",
        &threads,
        "--world",
    ];
    let mut troupe: Vec<&OsStr> = vec![me.as_os_str()];
    troupe.extend(flags.iter().map(OsStr::new));
    troupe.push(world.as_os_str());
    troupe.extend(label_args(label));
    let stage_cmd = [stage.as_os_str(), OsStr::new("-g"), copy.0.as_os_str()];
    let stage_what = format!(
        "Stage ({} -g {}; its controllers need LD_LIBRARY_PATH on Stage's lib/ and STAGEPATH on its plugins)",
        stage.display(),
        copy.0.display()
    );
    let (mut ours, mut theirs) = (Vec::new(), Vec::new());
    for _ in 0..a.pairs {
        theirs.push(measured(&me, &stage_cmd, &stage_what)?);
        ours.push(measured(&me, &troupe, "troupe bench stage --world")?);
    }
    let mut out = std::io::stdout().lock();
    if let Some(row) = ours[0].stdout.lines().find(|l| l.contains("real time")) {
        writeln!(out, "{row}")?;
    }
    let pair: Vec<f64> = theirs
        .iter()
        .zip(&ours)
        .map(|(s, t)| s.wall / t.wall)
        .collect();
    let (lo, hi) = pair.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &r| {
        (lo.min(r), hi.max(r))
    });
    let med = |runs: &[Run], f: fn(&Run) -> f64| median(runs.iter().map(f).collect());
    let (s_wall, t_wall) = (med(&theirs, |r| r.wall), med(&ours, |r| r.wall));
    let (s_cpu, t_cpu) = (med(&theirs, |r| r.cpu), med(&ours, |r| r.cpu));
    let (s_mb, t_mb) = (med(&theirs, |r| r.peak_mb), med(&ours, |r| r.peak_mb));
    writeln!(
        out,
        "  {name:<13} vs Stage: Stage {s_wall:.2} s ({s_cpu:.2} s CPU), {s_mb:.0} MB peak; Troupe {t_wall:.2} s ({t_cpu:.2} s CPU), {t_mb:.0} MB peak: {:.1}x as fast ({lo:.1}–{hi:.1}x pair by pair), {:.1}x less memory ({} pairs of whole processes in turn, {} simulated s, threads {})",
        s_wall / t_wall,
        s_mb / t_mb,
        pair.len(),
        a.seconds,
        a.threads
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn staged_sets_the_top_level_and_leaves_models_alone() {
        let world = "include \"../pioneer.inc\"\nspeedup 1 # real time\npaused 1\nthreads 7\n\
                     window ( size [10 10] )\nmodel ( name \"a(b\" threads 3\n  paused 1 )\n";
        let s = staged(world, 1, 60.0);
        let top: Vec<&str> = s
            .lines()
            .filter(|l| !l.starts_with(' ') && !l.starts_with('#'))
            .collect();
        assert_eq!(
            top,
            [
                "speedup -1",
                "paused 0",
                "threads 1",
                "quit_time 60",
                "include \"../pioneer.inc\"",
                "window ( size [10 10] )",
                "model ( name \"a(b\" threads 3",
            ]
        );
        // Inside the model (its name's parenthesis is text): kept.
        assert!(s.contains("\n  paused 1 )\n"), "{s}");
    }

    #[test]
    fn the_wander_cave_swaps_each_controller_and_no_comment() {
        let cave = "define rob fancypioneer2dx\n(\n ctrl \"expand_pioneer\" # not \"wander\"\n)\n\
                    # ctrl \"expand_pioneer\"\nrob( name \"a#1\" ctrl \"expand_pioneer\" )\n";
        let w = wandering(cave).expect("swapped");
        assert_eq!(w.matches("ctrl \"wander\"").count(), 2, "{w}");
        assert!(w.contains(" ctrl \"wander\" # not \"wander\"\n"), "{w}");
        assert!(w.contains("\n# ctrl \"expand_pioneer\"\n"), "{w}");
        assert!(w.contains("rob( name \"a#1\" ctrl \"wander\" )"), "{w}");
        assert_eq!(wandering("# ctrl \"expand_pioneer\"\nrob( )\n"), None);
    }

    #[test]
    fn median_of_odd_and_even() {
        assert_eq!(median(vec![3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(vec![4.0, 1.0, 2.0, 3.0]), 2.5);
        assert!(median(Vec::new()).is_nan());
    }
}
