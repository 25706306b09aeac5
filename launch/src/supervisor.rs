//! `troupe launch`: runs a plan as one child process per node.
//!
//! The launcher starts an embedded Zenoh router on tcp/127.0.0.1:7447 (unless
//! `--connect` points at another), then each node of this host's share in
//! start order, each once the devices it requires from the plan are live. It
//! watches liveliness to report readiness, prefixes every child's output with
//! the node's name, restarts nodes by their policy, and on SIGINT/SIGTERM
//! stops them in reverse start order: SIGTERM, a grace period, SIGKILL.
//! The Player TCP bridge for the plan's robots runs in the launcher itself,
//! on the router's session, once every device is live.
//! Children ask the kernel to SIGTERM them if the launcher dies
//! (PR_SET_PDEATHSIG), so no orphan survives a killed launcher.

use std::collections::BTreeSet;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Args;
use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;
use tokio::io::{AsyncBufReadExt, BufReader};
use tokio::process::Command;
use tokio::sync::watch;
use tokio::task::JoinHandle;
use troupe_msgs::{keys, Device};
use troupe_node::process::{StopSignals, SUPERVISOR_ENV};
use troupe_node::zenoh::pubsub::Subscriber;
use troupe_node::zenoh::{Session, Wait};
use troupe_node::{Mode, ZenohArgs};

use crate::catalog::Catalog;
use crate::plan::{self, NodeSpec, Policy};

/// Flags of `troupe launch`.
#[derive(Debug, Args)]
pub struct LaunchArgs {
    /// A Player .cfg file or a launch plan (.toml from `troupe plan`).
    pub file: PathBuf,
    /// Robot field (port) for addresses that give none, as `player -p PORT`.
    #[arg(short = 'p', long = "robot", value_name = "PORT", default_value_t = troupe_msgs::DEFAULT_ROBOT)]
    pub robot: u32,
    /// Start only the nodes placed on this host; the rest run elsewhere.
    #[arg(long, value_name = "NAME")]
    pub host: Option<String>,
    /// A device provided from outside this launch (repeatable), e.g. `laser:0`
    /// played back by `troupe play`: nodes that require it wait for it.
    #[arg(long, value_name = "ADDR")]
    pub external: Vec<String>,
    /// Every node follows `sim/clock` published from outside this launch
    /// (`troupe play` of a recording, a simulator on another host), as they
    /// do when the plan has a simulator.
    #[arg(long)]
    pub sim_time: bool,
    /// Print the plan and exit.
    #[arg(long)]
    pub dry_run: bool,
    /// Also write each node's output to DIR/<node>.log.
    #[arg(long, value_name = "DIR")]
    pub log_dir: Option<PathBuf>,
    /// Seconds to wait for every device to come up before reporting what is missing.
    #[arg(long, value_name = "SECS", default_value_t = 30.0, value_parser = troupe_node::args::seconds)]
    pub ready_timeout: f64,
    /// Seconds between SIGTERM and SIGKILL when stopping a node.
    #[arg(long, value_name = "SECS", default_value_t = 5.0, value_parser = troupe_node::args::seconds)]
    pub grace: f64,
    /// Serve no Player clients: start no TCP bridge on the robot ports.
    #[arg(long)]
    pub no_bridge: bool,
    /// Address the bridge's robot ports listen on (Player clients have no
    /// authentication: open other addresses only on a trusted network).
    #[arg(long, value_name = "ADDR", default_value = "127.0.0.1")]
    pub bridge_bind: std::net::IpAddr,
    /// Accept Player clients only from this network or address (repeatable,
    /// e.g. `--bridge-allow 10.1.0.0/16`); default: anyone who reaches it.
    #[arg(long, value_name = "CIDR", value_parser = troupe_bridge::parse_network)]
    pub bridge_allow: Vec<troupe_bridge::IpNetwork>,
    /// Player clients each robot port serves at once (see `troupe bridge
    /// --help`).
    #[arg(long, value_name = "N", default_value_t = troupe_bridge::DEFAULT_MAX_CLIENTS,
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..))]
    pub bridge_max_clients: usize,
    /// Let the bridge listen on free TCP ports instead of the robot numbers;
    /// it prints `troupe bridge: robot 6665 on ADDR:PORT` on stdout.
    #[arg(long)]
    pub bridge_any_port: bool,
    /// Run the simulator at this multiple of real time, whatever the world
    /// file says (1 = real time; 0 = Player's pace, 100 steps a second)
    #[arg(long, value_name = "X", value_parser = troupe_node::args::finite)]
    pub speedup: Option<f64>,
    /// Also serve `troupe view` (the running world in a browser) on ADDR:
    /// `--view` alone serves 127.0.0.1:8080, `--view=127.0.0.1:0` any free
    /// port. Its address is printed (`troupe view: http://…/`).
    #[arg(
        long,
        value_name = "ADDR",
        num_args = 0..=1,
        require_equals = true,
        default_missing_value = "127.0.0.1:8080"
    )]
    pub view: Option<std::net::SocketAddr>,
    /// Also serve `troupe foxglove` (the fleet live in Foxglove) on ADDR:
    /// `--foxglove` alone serves 127.0.0.1:8765, `--foxglove=127.0.0.1:0`
    /// any free port. Its address is printed (`troupe foxglove: ws://…`).
    #[arg(
        long,
        value_name = "ADDR",
        num_args = 0..=1,
        require_equals = true,
        default_missing_value = "127.0.0.1:8765"
    )]
    pub foxglove: Option<std::net::SocketAddr>,
    /// ROS 2: every node of the launch shows its devices to ROS 2 nodes.
    #[command(flatten)]
    pub ros2: troupe_node::Ros2Args,
}

/// Flags of `troupe plan`.
#[derive(Debug, Args)]
pub struct PlanArgs {
    /// A Player .cfg file (or a plan to check).
    pub file: PathBuf,
    /// Robot field (port) for addresses that give none, as `player -p PORT`.
    #[arg(short = 'p', long = "robot", value_name = "PORT", default_value_t = troupe_msgs::DEFAULT_ROBOT)]
    pub robot: u32,
}

/// `troupe plan`: prints the plan as TOML, warnings on stderr.
pub fn print_plan(a: PlanArgs, catalog: &Catalog) -> anyhow::Result<()> {
    let (plan, warnings) = plan::load(&a.file, a.robot, catalog)?;
    for w in warnings {
        let _ = writeln!(std::io::stderr(), "warning: {w}");
    }
    let mut out = std::io::stdout().lock();
    out.write_all(plan::to_toml(&plan).as_bytes())?;
    Ok(())
}

/// `troupe launch`.
pub fn launch(a: LaunchArgs, z: &ZenohArgs, catalog: &Catalog) -> anyhow::Result<()> {
    let (mut plan, warnings) = plan::load_with(&a.file, a.robot, &a.external, catalog)?;
    for w in &warnings {
        tracing::warn!("{w}");
    }
    if let Some(x) = a.speedup {
        set_speedup(&mut plan, x)?;
    }
    if a.dry_run {
        std::io::stdout()
            .lock()
            .write_all(plan::to_toml(&plan).as_bytes())?;
        return Ok(());
    }
    // Under a simulator (or a replay), every other node follows its clock.
    let sim_time = a.sim_time
        || plan
            .nodes
            .iter()
            .any(|n| catalog.find(&n.driver).is_some_and(|e| e.clock_source));
    let nodes: Vec<NodeSpec> = match &a.host {
        None => plan.nodes.clone(),
        Some(h) => {
            let homeless: Vec<&str> = plan
                .nodes
                .iter()
                .filter(|n| n.host.is_none())
                .map(|n| n.name.as_str())
                .collect();
            if !homeless.is_empty() {
                anyhow::bail!(
                    "with --host, every node needs a `host`; these have none: {}",
                    homeless.join(", ")
                );
            }
            plan.nodes
                .iter()
                .filter(|n| n.host.as_deref() == Some(h))
                .cloned()
                .collect()
        }
    };
    if nodes.is_empty() {
        anyhow::bail!(
            "no node of {} runs on host `{}`",
            a.file.display(),
            a.host.as_deref().unwrap_or("?")
        );
    }
    if let Some(d) = &a.log_dir {
        std::fs::create_dir_all(d)
            .with_context(|| format!("creating --log-dir {}", d.display()))?;
    }
    // The simulator (or a replay) keeps its own time; the rest follow it.
    let clocks: BTreeSet<String> = nodes
        .iter()
        .filter(|n| catalog.find(&n.driver).is_some_and(|e| e.clock_source))
        .map(|n| n.driver.clone())
        .collect();
    let ros2 = a.ros2.config(plan.launch.ros2.as_ref())?;
    if let Some(r) = &ros2 {
        tracing::info!(
            "ROS 2: every node shows its devices on domain {} ({}), robots in {}",
            r.domain,
            r.distro,
            r.namespace
        );
    }
    let ros2_args = ros2.map(|r| r.to_args()).unwrap_or_default();
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    rt.block_on(supervise(a, z.clone(), nodes, sim_time, clocks, ros2_args))
}

/// Overrides the `speedup` of every simulator in the plan (`--speedup`).
fn set_speedup(plan: &mut plan::Plan, x: f64) -> anyhow::Result<()> {
    if !x.is_finite() {
        anyhow::bail!("--speedup {x}: expected a number (1 = real time, 0 = as fast as possible)");
    }
    let mut any = false;
    for n in plan.nodes.iter_mut().filter(|n| n.driver == "stage") {
        if n.options.contains_key("worldfile") {
            n.options.insert("speedup".into(), x.into());
            any = true;
        }
    }
    if !any {
        anyhow::bail!("--speedup: the plan has no simulator (no `stage` driver with a worldfile)");
    }
    Ok(())
}

/// The shared view of which devices are live.
#[derive(Default)]
struct Live {
    devices: Mutex<BTreeSet<Device>>,
}

impl Live {
    /// Waits until every device of `needs` is live (`changed` ticks with
    /// each change); false when `stop` turned true first.
    async fn wait_for(
        &self,
        needs: &[Device],
        changed: &mut watch::Receiver<u64>,
        stop: &mut watch::Receiver<bool>,
    ) -> bool {
        loop {
            let missing = {
                let set = self.devices.lock().unwrap_or_else(|p| p.into_inner());
                needs.iter().any(|d| !set.contains(d))
            };
            if *stop.borrow() {
                return false;
            }
            if !missing {
                return true;
            }
            tokio::select! {
                _ = changed.changed() => {}
                _ = stop.changed() => {}
            }
        }
    }
}

struct NodeState {
    spec: NodeSpec,
    pid: Mutex<Option<u32>>,
    stopping: AtomicBool,
    failed: AtomicBool,
}

impl NodeState {
    fn new(spec: NodeSpec) -> NodeState {
        NodeState {
            spec,
            pid: Mutex::new(None),
            stopping: AtomicBool::new(false),
            failed: AtomicBool::new(false),
        }
    }
}

/// Runs the stack until a signal, or until every node is done on its own:
/// the network, the bridge and the viewers, the nodes in start order and the
/// readiness report; then stops it all in order and says how it went.
async fn supervise(
    a: LaunchArgs,
    z: ZenohArgs,
    specs: Vec<NodeSpec>,
    sim_time: bool,
    clocks: BTreeSet<String>,
    ros2_args: Vec<String>,
) -> anyhow::Result<()> {
    let started = Instant::now();
    let mut signals = StopSignals::new().context("catching SIGTERM and SIGINT")?;
    let Some((session, child_net)) = join_network(&z, &mut signals).await? else {
        return Ok(());
    };
    let (live, live_rx, liveliness) = watch_liveliness(&session)?;
    let (stop_tx, stop_rx) = watch::channel(false);
    let stack = Stack::new(specs, child_net, live, live_rx, stop_rx);
    let bridge = if a.no_bridge {
        None
    } else {
        stack.start_bridge(&a, &session)
    };
    let exe = std::env::current_exe().context("finding the troupe binary")?;
    let viewers = stack.start_viewers(&a, &exe);
    let mut tasks = stack.start_nodes(&a, &exe, sim_time, &clocks, &ros2_args);
    let reporter = stack.report_readiness(a.ready_timeout, started);

    let signalled = signal_or_all_done(&mut signals, &mut tasks).await;
    reporter.abort();
    // The bridge first: Player clients see the robot go, not a bridge
    // serving devices that are stopping.
    let _ = stop_tx.send(true);
    if let Some(b) = bridge {
        let _ = b.await;
    }
    let viewers_failed = await_viewers(viewers).await;
    if signalled {
        stack.stop_in_reverse_order(&mut tasks, a.grace).await;
    }
    drop(liveliness);
    let _ = session.close().await;
    stack.verdict(viewers_failed)
}

/// The network: an embedded router unless told to join another. The
/// launcher's session and its children's network flags; `None` when a
/// signal came before the router answered.
async fn join_network(
    z: &ZenohArgs,
    signals: &mut StopSignals,
) -> anyhow::Result<Option<(Session, Vec<String>)>> {
    let embedded = z.connect.is_empty() && z.zenoh_config.is_none();
    if embedded {
        return start_router(z).map(Some);
    }
    let Some(session) = signals
        .unless_stopped(z.open_in_background(Mode::Client))
        .await?
    else {
        return Ok(None);
    };
    Ok(Some((session, z.to_child_args())))
}

/// Starts the embedded router and says where it listens (on stdout): its
/// session and the network flags that connect the children to it.
fn start_router(z: &ZenohArgs) -> anyhow::Result<(Session, Vec<String>)> {
    let listen = if z.listen.is_empty() {
        vec![troupe_node::DEFAULT_ROUTER.to_owned()]
    } else {
        z.listen.clone()
    };
    // The namespace applies to the router's own session only (its
    // watcher and the bridge), not to what it routes for others.
    let rz = ZenohArgs {
        listen: listen.clone(),
        namespace: z.namespace.clone(),
        no_multicast: !z.multicast,
        multicast: z.multicast,
        ..Default::default()
    };
    let session = match rz.open(Mode::Router) {
        Ok(s) => s,
        Err(e) => return Err(router_not_started(&listen, z, e)),
    };
    let locators = troupe_node::locators(&session);
    // A line on stdout for scripts and tests that pass --listen …:0.
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "troupe launch: router listening on {}",
        locators.join(" ")
    )?;
    out.flush()?;
    drop(out);
    // The nodes take the launch's flags (--mode, --lease, --multicast…),
    // but connect to this router, and peers listen on loopback.
    let mut child = ZenohArgs {
        connect: locators,
        listen: Vec::new(),
        no_multicast: !z.multicast,
        ..z.clone()
    }
    .to_child_args();
    // A client listens on nothing: its data goes through the router.
    if z.mode != Some(Mode::Client) {
        child.extend(["--listen".into(), "tcp/127.0.0.1:0".into()]);
    }
    Ok((session, child))
}

/// The launcher's view of liveliness, in the plan's namespace: the live
/// devices, a receiver that ticks with each change, and the subscriber
/// that keeps them (dropping it stops the watch).
fn watch_liveliness(
    session: &Session,
) -> anyhow::Result<(Arc<Live>, watch::Receiver<u64>, Subscriber<()>)> {
    let live = Arc::new(Live::default());
    let (live_tx, live_rx) = watch::channel(0u64);
    let l = live.clone();
    let subscriber = session
        .liveliness()
        .declare_subscriber(keys::tokens(None))
        .history(true)
        .callback(move |s| {
            let Ok((dev, _)) = keys::parse_token(s.key_expr().as_str()) else {
                return;
            };
            let mut set = l.devices.lock().unwrap_or_else(|p| p.into_inner());
            match s.kind() {
                troupe_node::zenoh::sample::SampleKind::Put => set.insert(dev),
                troupe_node::zenoh::sample::SampleKind::Delete => set.remove(&dev),
            };
            drop(set);
            live_tx.send_modify(|g| *g += 1);
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("watching liveliness: {e}"))?;
    Ok((live, live_rx, subscriber))
}

/// Waits for SIGTERM or SIGINT (true) or for every node to be done on its
/// own (false). A finished task's handle is dropped (None), never polled
/// again.
async fn signal_or_all_done(
    signals: &mut StopSignals,
    tasks: &mut [Option<JoinHandle<()>>],
) -> bool {
    let all_done = async {
        for t in tasks.iter_mut() {
            if let Some(h) = t.as_mut() {
                let _ = h.await;
            }
            *t = None;
        }
    };
    tokio::select! {
        () = signals.recv() => true,
        _ = all_done => false,
    }
}

/// Waits for the view and the Foxglove server, which stop with the stack:
/// how those that failed are named (one that failed fails the launch).
async fn await_viewers(viewers: Vec<(Viewer, JoinHandle<bool>)>) -> Vec<&'static str> {
    let mut failed = Vec::new();
    for (v, task) in viewers {
        if !task.await.unwrap_or(false) {
            failed.push(v.failed);
        }
    }
    failed
}

/// What the launcher shares with the tasks it starts: this host's nodes,
/// the devices they provide, the children's network flags, liveliness and
/// the stop.
struct Stack {
    states: Vec<Arc<NodeState>>,
    local: BTreeSet<Device>,
    net: Vec<String>,
    live: Arc<Live>,
    live_rx: watch::Receiver<u64>,
    stop_rx: watch::Receiver<bool>,
}

impl Stack {
    /// The stack of the nodes `specs`, with the devices they provide.
    fn new(
        specs: Vec<NodeSpec>,
        net: Vec<String>,
        live: Arc<Live>,
        live_rx: watch::Receiver<u64>,
        stop_rx: watch::Receiver<bool>,
    ) -> Stack {
        let states: Vec<Arc<NodeState>> = specs
            .into_iter()
            .map(|spec| Arc::new(NodeState::new(spec)))
            .collect();
        let local: BTreeSet<Device> = states
            .iter()
            .flat_map(|s| {
                s.spec
                    .provides
                    .iter()
                    .filter_map(|r| keys::parse_data(&r.device).ok())
            })
            .collect();
        Stack {
            states,
            local,
            net,
            live,
            live_rx,
            stop_rx,
        }
    }

    /// Starts the Player bridge for the stack's robots, if it has any.
    fn start_bridge(&self, a: &LaunchArgs, session: &Session) -> Option<JoinHandle<()>> {
        bridge_config(a, &self.states).map(|cfg| {
            tokio::spawn(serve_bridge(
                session.clone(),
                cfg,
                self.live.clone(),
                self.live_rx.clone(),
                self.stop_rx.clone(),
                self.local.clone(),
            ))
        })
    }

    /// Starts the viewers asked for (`--view`, `--foxglove`), each with
    /// the task that tells whether it ran cleanly.
    fn start_viewers(&self, a: &LaunchArgs, exe: &Path) -> Vec<(Viewer, JoinHandle<bool>)> {
        // The view and the Foxglove server join as peers, on the nodes' network
        // flags, their listener on loopback as the nodes' (without --listen a
        // peer listens on every interface).
        [(Viewer::VIEW, a.view), (Viewer::FOXGLOVE, a.foxglove)]
            .into_iter()
            .filter_map(|(v, at)| {
                let at = at?;
                let run = run_viewer(
                    v,
                    exe.to_path_buf(),
                    self.net.clone(),
                    at,
                    self.stop_rx.clone(),
                );
                Some((v, tokio::spawn(run)))
            })
            .collect()
    }

    /// Starts a task for each node, in the plan's order: it waits for what
    /// the node requires, then runs it. Their handles (None once done).
    fn start_nodes(
        &self,
        a: &LaunchArgs,
        exe: &Path,
        sim_time: bool,
        clocks: &BTreeSet<String>,
        ros2_args: &[String],
    ) -> Vec<Option<JoinHandle<()>>> {
        let mut tasks = Vec::new();
        for st in &self.states {
            let ctx = NodeCtx {
                exe: exe.to_path_buf(),
                net: self.net.clone(),
                log_dir: a.log_dir.clone(),
                live: self.live.clone(),
                live_rx: self.live_rx.clone(),
                stop_rx: self.stop_rx.clone(),
                local: self.local.clone(),
                sim_time: sim_time && !clocks.contains(&st.spec.driver),
                ros2: ros2_args.to_vec(),
            };
            tasks.push(Some(tokio::spawn(run_node(st.clone(), ctx))));
        }
        tasks
    }

    /// Starts the readiness report, which waits `ready_timeout` seconds
    /// (at least 0.1) for every device of the stack.
    fn report_readiness(&self, ready_timeout: f64, started: Instant) -> JoinHandle<()> {
        let all: BTreeSet<Device> = self.local.clone();
        let (live, rx, states) = (self.live.clone(), self.live_rx.clone(), self.states.clone());
        let timeout = Duration::from_secs_f64(ready_timeout.max(0.1));
        tokio::spawn(report_ready(live, rx, states, all, timeout, started))
    }

    /// After a signal: stops the nodes in reverse start order, SIGKILLing
    /// those that outlive SIGTERM by `grace` seconds.
    async fn stop_in_reverse_order(&self, tasks: &mut [Option<JoinHandle<()>>], grace: f64) {
        let states = &self.states;
        tracing::info!("stopping {} nodes in reverse start order", states.len());
        let grace = Duration::from_secs_f64(grace.max(0.0));
        let mut orders: Vec<u32> = states.iter().map(|s| s.spec.start_order).collect();
        orders.sort_unstable();
        orders.dedup();
        for o in orders.into_iter().rev() {
            let group: Vec<usize> = (0..states.len())
                .filter(|&i| states[i].spec.start_order == o)
                .collect();
            self.stop_group(&group, tasks, grace).await;
        }
    }

    /// Stops the nodes `group` (indices of one start order) together:
    /// SIGTERM, then SIGKILL for those still running after `grace`.
    async fn stop_group(
        &self,
        group: &[usize],
        tasks: &mut [Option<JoinHandle<()>>],
        grace: Duration,
    ) {
        let states = &self.states;
        for &i in group {
            states[i].stopping.store(true, Ordering::SeqCst);
            signal(&states[i], Signal::SIGTERM);
        }
        // A node's task ends once its process has exited.
        let deadline = tokio::time::Instant::now() + grace;
        for &i in group {
            let Some(mut h) = tasks[i].take() else {
                continue;
            };
            if tokio::time::timeout_at(deadline, &mut h).await.is_err() {
                let s = &states[i];
                tracing::warn!(
                    "node `{}` ignored SIGTERM for {grace:?}; killing it",
                    s.spec.name
                );
                signal(s, Signal::SIGKILL);
                s.failed.store(true, Ordering::SeqCst);
                let _ = h.await;
            }
        }
    }

    /// How the launch went: an error naming the nodes and viewers that
    /// failed, if any did.
    fn verdict(&self, viewers_failed: Vec<&'static str>) -> anyhow::Result<()> {
        let mut failed: Vec<&str> = self
            .states
            .iter()
            .filter(|s| s.failed.load(Ordering::SeqCst))
            .map(|s| s.spec.name.as_str())
            .collect();
        failed.extend(viewers_failed);
        if failed.is_empty() {
            tracing::info!("stack stopped cleanly");
            Ok(())
        } else {
            anyhow::bail!(
                "the stack did not run cleanly: {} failed",
                failed.join(", ")
            )
        }
    }
}

/// The readiness report: a line once every device of `all` is live, or,
/// after `timeout`, an error for each node that has not brought up its own.
async fn report_ready(
    live: Arc<Live>,
    mut rx: watch::Receiver<u64>,
    states: Vec<Arc<NodeState>>,
    all: BTreeSet<Device>,
    timeout: Duration,
    started: Instant,
) {
    let deadline = tokio::time::Instant::now() + timeout;
    loop {
        let missing: Vec<Device> = {
            let set = live.devices.lock().unwrap_or_else(|p| p.into_inner());
            all.iter().filter(|d| !set.contains(d)).copied().collect()
        };
        if missing.is_empty() {
            tracing::info!(
                "all {} nodes up, {} devices live, {:.2} s after launch",
                states.len(),
                all.len(),
                started.elapsed().as_secs_f64()
            );
            return;
        }
        if tokio::time::timeout_at(deadline, rx.changed())
            .await
            .is_err()
        {
            report_missing(&states, &missing, timeout);
            return;
        }
    }
}

/// Names, for each node, the devices of `missing` it has not brought up
/// within `timeout`.
fn report_missing(states: &[Arc<NodeState>], missing: &[Device], timeout: Duration) {
    for s in states {
        let m: Vec<String> = s
            .spec
            .provides
            .iter()
            .filter_map(|r| keys::parse_data(&r.device).ok())
            .filter(|d| missing.contains(d))
            .map(|d| d.to_string())
            .collect();
        if !m.is_empty() {
            tracing::error!(
                "node `{}` has not brought up {} after {:.0} s (see its log lines above; --ready-timeout sets the wait)",
                s.spec.name,
                listed(&m, 8),
                timeout.as_secs_f64()
            );
        }
    }
}

/// The first `most` of `items`, and how many more: a world of 10,000
/// robots is not named device by device.
pub fn listed(items: &[String], most: usize) -> String {
    match items.len().checked_sub(most) {
        Some(more) if more > 0 => format!("{} and {more} more", items[..most].join(", ")),
        _ => items.join(", "),
    }
}

/// `troupe` with the launch's network flags `net`, as the launcher runs
/// its children: supervised (it dies with the launcher), its output piped
/// to be forwarded, in a process group of its own (a terminal's Ctrl-C
/// reaches only the launcher, which stops its children in order), killed
/// if its handle is dropped.
fn troupe_child(exe: &std::path::Path, net: &[String]) -> Command {
    let mut cmd = Command::new(exe);
    cmd.args(net)
        .env(SUPERVISOR_ENV, std::process::id().to_string())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .process_group(0)
        .kill_on_drop(true);
    cmd
}

/// The longest section passed as an argument; longer ones go through the
/// node's stdin (`--section -`). Linux takes at most 128 KiB in one.
const SECTION_ARG_MAX: usize = 100_000;

/// A viewer the launcher may serve beside the stack.
#[derive(Debug, Clone, Copy)]
struct Viewer {
    /// Its command: `view`.
    command: &'static str,
    /// How a failure is named: `the view (--view)`.
    failed: &'static str,
}

impl Viewer {
    const VIEW: Viewer = Viewer {
        command: "view",
        failed: "the view (--view)",
    };
    const FOXGLOVE: Viewer = Viewer {
        command: "foxglove",
        failed: "the Foxglove server (--foxglove)",
    };
}

/// `launch --view`, `launch --foxglove`: runs `troupe view` (or `troupe
/// foxglove`) on `at` until the launch stops (then SIGTERM, and SIGKILL if
/// it has not gone within 5 s). Its address line goes to the launcher's
/// stdout, its log to stderr as a node's. Whether it ran until asked to
/// stop, and then stopped cleanly.
async fn run_viewer(
    v: Viewer,
    exe: PathBuf,
    net: Vec<String>,
    at: std::net::SocketAddr,
    mut stop_rx: watch::Receiver<bool>,
) -> bool {
    let name = v.command;
    let mut child = match troupe_child(&exe, &net)
        .args([
            name,
            "--bind",
            &at.ip().to_string(),
            "--port",
            &at.port().to_string(),
        ])
        .spawn()
    {
        Ok(c) => c,
        Err(e) => {
            tracing::error!("--{name}: cannot start `troupe {name}`: {e}");
            return false;
        }
    };
    let mut forwarders = Vec::new();
    if let Some(out) = child.stdout.take() {
        forwarders.push(tokio::spawn(async move {
            let mut lines = BufReader::new(out).lines();
            while let Ok(Some(line)) = lines.next_line().await {
                let mut o = std::io::stdout().lock();
                let _ = writeln!(o, "{line}");
                let _ = o.flush();
            }
        }));
    }
    if let Some(err) = child.stderr.take() {
        forwarders.push(tokio::spawn(forward(
            BufReader::new(err),
            name.to_owned(),
            None,
        )));
    }
    let pid = child.id().and_then(|p| i32::try_from(p).ok());
    let ok = tokio::select! {
        status = child.wait() => {
            // It ended on its own (a taken port, a stopped network): the
            // stack runs on without it.
            let how = status.map_or_else(|e| e.to_string(), |s| s.to_string());
            tracing::error!("`troupe {name}` ended ({how}); the stack runs on without it");
            false
        }
        _ = async { stop_rx.wait_for(|&stop| stop).await.map(|_| ()) } => {
            if let Some(p) = pid {
                let _ = kill(Pid::from_raw(p), Signal::SIGTERM);
            }
            match tokio::time::timeout(Duration::from_secs(5), child.wait()).await {
                Ok(Ok(s)) if s.success() => true,
                Ok(status) => {
                    let how = status.map_or_else(|e| e.to_string(), |s| s.to_string());
                    tracing::warn!("`troupe {name}` stopped: {how}");
                    false
                }
                Err(_) => {
                    tracing::warn!("`troupe {name}` ignored SIGTERM for 5 s; killing it");
                    let _ = child.kill().await;
                    false
                }
            }
        }
    };
    for f in forwarders {
        let _ = f.await;
    }
    ok
}

fn signal(s: &NodeState, sig: Signal) {
    if let Some(pid) = *s.pid.lock().unwrap_or_else(|p| p.into_inner()) {
        if let Ok(p) = i32::try_from(pid) {
            let _ = kill(Pid::from_raw(p), sig);
        }
    }
}

struct NodeCtx {
    exe: PathBuf,
    net: Vec<String>,
    log_dir: Option<PathBuf>,
    live: Arc<Live>,
    live_rx: watch::Receiver<u64>,
    stop_rx: watch::Receiver<bool>,
    local: BTreeSet<Device>,
    sim_time: bool,
    /// `--ros2` and its settings, for every node.
    ros2: Vec<String>,
}

/// Runs one node: waits for its requirements, starts it, forwards its
/// output, restarts it by its policy.
async fn run_node(st: Arc<NodeState>, mut ctx: NodeCtx) {
    let name = st.spec.name.clone();
    let needs: Vec<Device> = st
        .spec
        .requires
        .iter()
        .filter_map(|r| keys::parse_data(&r.device).ok())
        .filter(|d| ctx.local.contains(d))
        .collect();
    // Start order: wait until what we require from this launch is live.
    if !ctx
        .live
        .wait_for(&needs, &mut ctx.live_rx, &mut ctx.stop_rx)
        .await
    {
        return;
    }
    let section = match st.spec.section() {
        Ok(s) => s,
        Err(e) => {
            tracing::error!("node `{name}`: {e}");
            st.failed.store(true, Ordering::SeqCst);
            return;
        }
    };
    let section_json = serde_json::to_string(&section).unwrap_or_default();
    let log = ctx.log_dir.as_ref().and_then(|d| {
        let p = d.join(format!("{name}.log"));
        match std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&p)
        {
            Ok(f) => Some(Arc::new(Mutex::new(f))),
            Err(e) => {
                tracing::warn!("cannot write {}: {e}", p.display());
                None
            }
        }
    });
    let policy = st.spec.restart.clone();
    let base_backoff = Duration::from_secs_f64(policy.backoff.clamp(0.0, 60.0));
    let mut backoff = base_backoff;
    let mut recent: Vec<Instant> = Vec::new();
    loop {
        if st.stopping.load(Ordering::SeqCst) {
            return;
        }
        let mut cmd = troupe_child(&ctx.exe, &ctx.net);
        // A large section (a world of 10,000 robots' stage sections) goes
        // through the node's stdin: one argument may hold 128 KiB.
        let piped = section_json.len() > SECTION_ARG_MAX;
        if piped {
            cmd.args(["node", &st.spec.driver, "--section", "-"])
                .stdin(Stdio::piped());
        } else {
            cmd.args(["node", &st.spec.driver, "--section", &section_json]);
        }
        if ctx.sim_time {
            cmd.arg("--sim-time");
        }
        cmd.args(&ctx.ros2);
        let t0 = Instant::now();
        let mut child = match cmd.spawn() {
            Ok(c) => c,
            Err(e) => {
                tracing::error!("node `{name}`: cannot start: {e}");
                st.failed.store(true, Ordering::SeqCst);
                return;
            }
        };
        if let Some(mut stdin) = child.stdin.take() {
            let text = section_json.clone();
            tokio::spawn(async move {
                use tokio::io::AsyncWriteExt;
                // A node that dies first is reported by its exit.
                let _ = stdin.write_all(text.as_bytes()).await;
            });
        }
        *st.pid.lock().unwrap_or_else(|p| p.into_inner()) = child.id();
        tracing::info!(
            "started node `{name}` ({}) pid {}",
            st.spec.driver,
            child.id().unwrap_or(0)
        );
        let mut forwarders = Vec::new();
        if let Some(out) = child.stdout.take() {
            forwarders.push(tokio::spawn(forward(
                BufReader::new(out),
                name.clone(),
                log.clone(),
            )));
        }
        if let Some(err) = child.stderr.take() {
            forwarders.push(tokio::spawn(forward(
                BufReader::new(err),
                name.clone(),
                log.clone(),
            )));
        }
        let status = child.wait().await;
        for f in forwarders {
            let _ = f.await;
        }
        *st.pid.lock().unwrap_or_else(|p| p.into_inner()) = None;
        let ok = status.as_ref().is_ok_and(|s| s.success());
        let how = match &status {
            Ok(s) => s.to_string(),
            Err(e) => e.to_string(),
        };
        if st.stopping.load(Ordering::SeqCst) {
            if !ok {
                tracing::warn!("node `{name}` stopped: {how}");
                st.failed.store(true, Ordering::SeqCst);
            }
            return;
        }
        let again = match policy.policy {
            Policy::Never => false,
            Policy::OnFailure => !ok,
            Policy::Always => true,
        };
        if !again {
            if ok {
                tracing::info!("node `{name}` exited ({how})");
            } else {
                tracing::error!("node `{name}` failed ({how}); its restart policy is `never`");
                st.failed.store(true, Ordering::SeqCst);
            }
            return;
        }
        let now = Instant::now();
        recent.retain(|t| now.duration_since(*t).as_secs_f64() < policy.window);
        if recent.len() as u32 >= policy.max {
            tracing::error!(
                "node `{name}` ({how}) restarted {} times within {:.0} s; giving up",
                recent.len(),
                policy.window
            );
            st.failed.store(true, Ordering::SeqCst);
            return;
        }
        recent.push(now);
        backoff = if t0.elapsed() > Duration::from_secs(10) {
            base_backoff
        } else {
            backoff
        };
        tracing::warn!(
            "node `{name}` {how}; restarting in {:.1} s",
            backoff.as_secs_f64()
        );
        tokio::select! {
            _ = tokio::time::sleep(backoff) => {}
            _ = ctx.stop_rx.changed() => return,
        }
        backoff = (backoff * 2).min(Duration::from_secs(5));
    }
}

/// The Player TCP bridge for the robots of `states`: Player listened on
/// every robot port of its .cfg, so `troupe launch` does too. DEVLIST lists
/// devices in the .cfg's order.
fn bridge_config(a: &LaunchArgs, states: &[Arc<NodeState>]) -> Option<troupe_bridge::Config> {
    let provided: Vec<Device> = states
        .iter()
        .flat_map(|s| s.spec.provides.iter())
        .filter_map(|r| keys::parse_data(&r.device).ok())
        .collect();
    let mut robots: Vec<u32> = provided.iter().map(|d| d.robot).collect();
    robots.sort_unstable();
    robots.dedup();
    if robots.is_empty() {
        return None;
    }
    let ports = robots
        .iter()
        .map(|&robot| {
            let port = match u16::try_from(robot) {
                _ if a.bridge_any_port => 0,
                Ok(p) => p,
                Err(_) => {
                    tracing::warn!("robot {robot} is not a TCP port: its bridge takes a free one");
                    0
                }
            };
            troupe_bridge::Port {
                robot,
                listen: std::net::SocketAddr::new(a.bridge_bind, port),
            }
        })
        .collect();
    Some(troupe_bridge::Config {
        ports,
        order: provided,
        allow: a.bridge_allow.clone(),
        max_clients: a.bridge_max_clients,
        ..Default::default()
    })
}

/// Runs the bridge inside the launcher, on its router's session: a request
/// from a Player client reaches the driver in one Zenoh hop, not the two a
/// client of the router takes, and the router knows every device token, so
/// DEVLIST is complete from the first request. The ports open once every
/// device of this launch is live, as Player's did once its drivers were set
/// up, and close when `stop` turns true.
async fn serve_bridge(
    session: troupe_node::zenoh::Session,
    cfg: troupe_bridge::Config,
    live: Arc<Live>,
    mut live_rx: watch::Receiver<u64>,
    mut stop: watch::Receiver<bool>,
    local: BTreeSet<Device>,
) {
    let local: Vec<Device> = local.into_iter().collect();
    if !live.wait_for(&local, &mut live_rx, &mut stop).await {
        return;
    }
    let bridge = match troupe_bridge::Bridge::bind(session, cfg).await {
        Ok(b) => b,
        Err(e) => {
            tracing::error!(
                "no Player bridge: {e}; --bridge-any-port takes free ports, --no-bridge starts none"
            );
            return;
        }
    };
    troupe_bridge::command::announce(&bridge);
    bridge
        .run(async move {
            let _ = stop.wait_for(|&s| s).await;
        })
        .await;
}

/// Copies a child's output lines to our stderr, prefixed by the node name.
async fn forward<R: tokio::io::AsyncRead + Unpin>(
    reader: BufReader<R>,
    name: String,
    log: Option<Arc<Mutex<std::fs::File>>>,
) {
    let mut lines = reader.lines();
    while let Ok(Some(line)) = lines.next_line().await {
        // A closed stderr must not stop the forwarding to the log file.
        let _ = writeln!(std::io::stderr().lock(), "{name:>12} | {line}");
        if let Some(f) = &log {
            let mut f = f.lock().unwrap_or_else(|p| p.into_inner());
            if let Err(e) = writeln!(f, "{line}") {
                tracing::warn!("log file of `{name}`: {e}");
            }
        }
    }
}

/// Why the embedded router did not start, said as what to do: a router
/// already there is one to join (or to keep apart from), a port another
/// program holds needs another port.
fn router_not_started(
    listen: &[String],
    z: &ZenohArgs,
    e: troupe_node::NodeError,
) -> anyhow::Error {
    let taken = listen.iter().find(|ep| {
        ep.strip_prefix("tcp/")
            .and_then(|addr| addr.parse::<std::net::SocketAddr>().ok())
            .is_some_and(|addr| {
                std::net::TcpListener::bind(addr)
                    .is_err_and(|b| b.kind() == std::io::ErrorKind::AddrInUse)
            })
    });
    let Some(ep) = taken else {
        return anyhow::Error::new(e).context(format!(
            "starting the embedded router on {}",
            listen.join(", ")
        ));
    };
    let router_there = ZenohArgs {
        connect: vec![ep.clone()],
        namespace: z.namespace.clone(),
        no_multicast: true,
        ..Default::default()
    }
    .open(Mode::Client)
    .is_ok();
    if router_there {
        anyhow::anyhow!(
            "a Zenoh router is already running on {ep} (another `troupe launch` or `troupe router`): \
             join it with `--connect {ep}` (add `--namespace NS` to keep the two stacks apart), \
             or start a separate one with `--listen tcp/127.0.0.1:PORT`"
        )
    } else {
        anyhow::anyhow!(
            "{ep} is taken by another program (not a Zenoh router): start the embedded router \
             elsewhere with `--listen tcp/127.0.0.1:PORT`"
        )
    }
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    fn sample(name: &str) -> crate::plan::Plan {
        let p = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../worlds")
            .join(name);
        crate::plan::load(&p, 6665, &crate::catalog::tests::catalog())
            .expect("sample plan")
            .0
    }

    #[test]
    fn speedup_overrides_the_simulator_and_only_it() {
        let mut plan = sample("simple.cfg");
        super::set_speedup(&mut plan, 5.0).expect("a simulator");
        for n in &plan.nodes {
            let want = (n.driver == "stage").then(|| serde_json::json!(5.0));
            assert_eq!(n.options.get("speedup").cloned(), want, "{}", n.name);
        }
    }

    #[test]
    fn a_long_list_is_cut_with_a_count() {
        let items: Vec<String> = (0..20).map(|i| format!("{}:ranger:0", 6665 + i)).collect();
        assert_eq!(
            super::listed(&items[..2], 8),
            "6665:ranger:0, 6666:ranger:0"
        );
        let said = super::listed(&items, 8);
        assert!(said.ends_with("6672:ranger:0 and 12 more"), "{said}");
        assert_eq!(super::listed(&items[..8], 8).matches(", ").count(), 7);
    }

    #[test]
    fn speedup_without_a_simulator_or_a_number_is_refused() {
        let mut plan = sample("laser.cfg");
        let e = super::set_speedup(&mut plan, 5.0).expect_err("no simulator");
        assert!(e.to_string().contains("no simulator"), "{e}");
        let mut plan = sample("simple.cfg");
        let e = super::set_speedup(&mut plan, f64::NAN).expect_err("NaN");
        assert!(e.to_string().contains("expected a number"), "{e}");
    }
}
