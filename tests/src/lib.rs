//! Support for Troupe's integration tests: a router per test on an ephemeral
//! loopback port, a namespace per test, the `troupe` binary, child processes
//! that die with the test, and deadlines instead of sleeps.

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{mpsc, Once};
use std::time::{Duration, Instant};

use troupe_node::zenoh::{Session, Wait};
use troupe_node::{Mode, ZenohArgs};

/// The longest any single wait in a test may take.
pub const DEADLINE: Duration = Duration::from_secs(20);

static COUNTER: AtomicU32 = AtomicU32::new(0);

pub use troupe_node::testing::{cannot_run, compat, in_ci};

/// A namespace no other test (or test run) uses.
pub fn unique_namespace(name: &str) -> String {
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    format!("test-{name}-{}-{n}", std::process::id())
}

/// A Zenoh router on `tcp/127.0.0.1:<ephemeral>` and a namespace, for one test.
pub struct TestNet {
    /// The router's session.
    pub router: Session,
    /// Where to connect: the router's real locator.
    pub endpoint: String,
    /// This test's namespace.
    pub namespace: String,
}

impl TestNet {
    /// Starts the router.
    pub fn new(name: &str) -> Self {
        let args = ZenohArgs {
            listen: vec!["tcp/127.0.0.1:0".into()],
            no_multicast: true,
            ..Default::default()
        };
        let router = args.open(Mode::Router).expect("router session");
        let endpoint = troupe_node::locators(&router)
            .into_iter()
            .next()
            .expect("router locator");
        TestNet {
            router,
            endpoint,
            namespace: unique_namespace(name),
        }
    }

    /// Flags that join this test's network and namespace.
    pub fn args(&self) -> ZenohArgs {
        ZenohArgs {
            connect: vec![self.endpoint.clone()],
            listen: vec!["tcp/127.0.0.1:0".into()],
            namespace: Some(self.namespace.clone()),
            no_multicast: true,
            ..Default::default()
        }
    }

    /// The same flags for a child `troupe` process.
    pub fn child_args(&self) -> Vec<String> {
        let mut v = self.args().to_child_args();
        v.extend(["--listen".into(), "tcp/127.0.0.1:0".into()]);
        v
    }

    /// A peer session in this test's namespace.
    pub fn peer(&self) -> Session {
        self.args().open(Mode::Peer).expect("peer session")
    }

    /// A client session in this test's namespace.
    pub fn client(&self) -> Session {
        let mut a = self.args();
        a.listen.clear();
        a.open(Mode::Client).expect("client session")
    }

    /// Waits until every device in `devices` has a liveliness token.
    pub fn wait_live(&self, devices: &[&str]) {
        wait_live(&self.client(), devices);
    }
}

/// Waits (within the deadline) until every device in `devices` (as
/// `6665:laser:0`) has a liveliness token, as `session` sees them.
pub fn wait_live(session: &Session, devices: &[&str]) {
    let sub = token_events(session);
    let deadline = Instant::now() + DEADLINE;
    let mut missing: Vec<String> = devices.iter().map(|d| d.to_string()).collect();
    while !missing.is_empty() {
        let sample = sub
            .recv_deadline(deadline)
            .expect("liveliness channel")
            .unwrap_or_else(|| panic!("devices never came up: {missing:?}"));
        if let Ok((d, _)) = troupe_msgs::keys::parse_token(sample.key_expr().as_str()) {
            missing.retain(|m| *m != d.to_string());
        }
    }
}

/// The `troupe` binary of this build, built once per test run.
pub fn troupe_bin() -> PathBuf {
    build_dir().join("troupe")
}

/// The example program `name` of this build (`target/<profile>/examples/<name>`).
pub fn example_bin(name: &str) -> PathBuf {
    build_dir().join("examples").join(name)
}

/// `target/<profile>`, after building the workspace's binaries and examples
/// there once per test process.
///
/// The build is `cargo build --workspace --bins --examples`: its features are
/// the ones `cargo test --workspace` resolves, so under that command it finds
/// every artifact fresh and only links `troupe`. A narrower build (`-p troupe`)
/// would resolve other features and compile the whole dependency tree again.
fn build_dir() -> PathBuf {
    static BUILD: Once = Once::new();
    // target/<profile>/deps/integration-… → target/<profile>
    let exe = std::env::current_exe().expect("test exe");
    let dir = exe.parent().and_then(|d| d.parent()).expect("target dir");
    BUILD.call_once(|| {
        let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
        let mut cmd = Command::new(cargo);
        cmd.args(["build", "--quiet", "--workspace", "--bins", "--examples"]);
        if dir.ends_with("release") {
            cmd.arg("--release");
        }
        let status = cmd.status().expect("running cargo build");
        assert!(
            status.success(),
            "cargo build of the workspace's binaries failed"
        );
    });
    dir.to_path_buf()
}

/// `troupe launch CFG EXTRA…` in namespace `ns`, with its router and its
/// Player bridge on free ports (it prints where on stdout).
pub fn launch(ns: &str, cfg: &std::path::Path, extra: &[&str]) -> Proc {
    let mut args = strings(&[
        "--namespace",
        ns,
        "launch",
        cfg.to_str().expect("a UTF-8 path"),
        "--listen",
        "tcp/127.0.0.1:0",
        "--bridge-any-port",
    ]);
    args.extend(strings(extra));
    Proc::troupe("launch", &args)
}

/// The router endpoint and the bridge's address for robot 6665 that a
/// [`launch`]ed launcher prints, in whichever order.
pub fn launch_ports(launcher: &mut Proc) -> (String, std::net::SocketAddr) {
    let lines = launcher.lines();
    let (mut router, mut player) = (None, None);
    let deadline = Instant::now() + DEADLINE;
    while router.is_none() || player.is_none() {
        let left = deadline.saturating_duration_since(Instant::now());
        let line = lines.recv_timeout(left).expect("the launcher's port lines");
        if let Some(rest) = line.strip_prefix("troupe launch: router listening on ") {
            router = rest.split_whitespace().next().map(str::to_owned);
        } else if let Some(rest) = line.strip_prefix("troupe bridge: robot 6665 on ") {
            player = rest.trim().parse().ok();
        }
    }
    (
        router.unwrap_or_default(),
        player.expect("a bridge address"),
    )
}

/// A stream's lines, read on a thread of their own.
fn line_channel(r: impl std::io::Read + Send + 'static) -> mpsc::Receiver<String> {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(r).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    rx
}

/// A child process that is killed when dropped, so a failing test leaves no orphan.
pub struct Proc {
    /// The child.
    pub child: Child,
    /// What it is, for messages.
    pub name: String,
}

impl Proc {
    /// Starts `troupe ARGS…` with piped stdout and stderr.
    pub fn troupe(name: &str, args: &[String]) -> Proc {
        Self::start(name, Command::new(troupe_bin()).args(args))
    }

    /// Starts `troupe ARGS…` inside network namespace `ns` (`ip netns exec`).
    pub fn troupe_in(ns: &str, name: &str, args: &[String]) -> Proc {
        let mut cmd = Command::new("ip");
        cmd.args(["netns", "exec", ns]).arg(troupe_bin()).args(args);
        Self::start(name, &mut cmd)
    }

    /// Starts `cmd` with piped stdout and stderr.
    pub fn start(name: &str, cmd: &mut Command) -> Proc {
        let child = cmd
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawning troupe");
        Proc {
            child,
            name: name.to_owned(),
        }
    }

    /// The CPU time the child has used so far (user and system), seconds.
    pub fn cpu_seconds(&self) -> f64 {
        let stat = std::fs::read_to_string(format!("/proc/{}/stat", self.child.id()))
            .unwrap_or_else(|e| panic!("{}: /proc/{}/stat: {e}", self.name, self.child.id()));
        // Fields 14 and 15 (utime, stime), counted after the command's ")".
        let ticks: u64 = stat
            .rsplit_once(") ")
            .map(|(_, rest)| {
                rest.split(' ')
                    .skip(11)
                    .take(2)
                    .filter_map(|t| t.parse::<u64>().ok())
                    .sum()
            })
            .unwrap_or(0);
        let hz = nix::unistd::sysconf(nix::unistd::SysconfVar::CLK_TCK)
            .ok()
            .flatten()
            .unwrap_or(100);
        ticks as f64 / hz as f64
    }

    /// The child's stdout, line by line, read on a thread.
    pub fn lines(&mut self) -> mpsc::Receiver<String> {
        line_channel(self.child.stdout.take().expect("stdout piped"))
    }

    /// The child's stderr (its log), line by line, read on a thread.
    pub fn err_lines(&mut self) -> mpsc::Receiver<String> {
        line_channel(self.child.stderr.take().expect("stderr piped"))
    }

    /// The first line the child prints on stdout, within the deadline.
    pub fn first_line(&mut self) -> String {
        let out = self.child.stdout.take().expect("stdout piped");
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            let mut line = String::new();
            let _ = BufReader::new(out).read_line(&mut line);
            let _ = tx.send(line);
        });
        rx.recv_timeout(DEADLINE)
            .unwrap_or_else(|_| panic!("{} printed nothing within {DEADLINE:?}", self.name))
    }

    /// The first locator of the child's banner (`<banner> tcp/… tcp/…`), e.g.
    /// "troupe router listening on" — how routers on port 0 say where they are.
    pub fn endpoint(&mut self, banner: &str) -> String {
        let line = self.first_line();
        line.trim()
            .strip_prefix(banner)
            .and_then(|rest| rest.split_whitespace().next())
            .unwrap_or_else(|| panic!("{}: expected `{banner} …`, got {line:?}", self.name))
            .to_owned()
    }

    /// Sends SIGTERM and waits (within the deadline) for the exit status.
    pub fn terminate(&mut self) -> std::process::ExitStatus {
        self.term();
        self.wait()
    }

    /// Sends SIGTERM, and does not wait.
    pub fn term(&self) {
        use nix::sys::signal::{kill, Signal};
        use nix::unistd::Pid;
        let pid = Pid::from_raw(i32::try_from(self.child.id()).expect("pid"));
        kill(pid, Signal::SIGTERM).expect("kill -TERM");
    }

    /// Waits (within the deadline) for the child to exit.
    pub fn wait(&mut self) -> std::process::ExitStatus {
        let (tx, rx) = mpsc::channel();
        let pid = self.child.id();
        // Child::wait needs &mut; reap it on this thread, watch the clock on another.
        let watchdog = std::thread::spawn(move || {
            if rx.recv_timeout(DEADLINE).is_err() {
                use nix::sys::signal::{kill, Signal};
                let _ = kill(nix::unistd::Pid::from_raw(pid as i32), Signal::SIGKILL);
            }
        });
        let status = self.child.wait().expect("wait");
        let _ = tx.send(());
        let _ = watchdog.join();
        status
    }

    /// Waits (within the deadline) for the child to exit: its status,
    /// everything it wrote on stdout, and on stderr.
    pub fn output(mut self) -> (std::process::ExitStatus, String, String) {
        let mut out = self.child.stdout.take().expect("stdout piped");
        let reader = std::thread::spawn(move || {
            let mut s = String::new();
            let _ = std::io::Read::read_to_string(&mut out, &mut s);
            s
        });
        let status = self.wait();
        let stdout = reader.join().unwrap_or_default();
        let stderr = self.stderr();
        (status, stdout, stderr)
    }

    /// Everything the child wrote on stderr. A child still running is
    /// stopped first: its stderr ends only when it exits, so reading it
    /// earlier (in a failing assertion's message) would wait forever.
    pub fn stderr(&mut self) -> String {
        if let Ok(None) = self.child.try_wait() {
            self.terminate();
        }
        let mut s = String::new();
        if let Some(mut e) = self.child.stderr.take() {
            let _ = std::io::Read::read_to_string(&mut e, &mut s);
        }
        s
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// Runs `troupe ARGS…` to completion (within the deadline): status, stdout, stderr.
pub fn troupe_output(args: &[String]) -> (std::process::ExitStatus, String, String) {
    Proc::troupe("troupe", args).output()
}

/// A client session of the router at `endpoint`, in namespace `ns`.
pub fn client_at(endpoint: &str, ns: &str) -> Session {
    ZenohArgs {
        connect: vec![endpoint.to_owned()],
        namespace: Some(ns.to_owned()),
        no_multicast: true,
        ..Default::default()
    }
    .open(Mode::Client)
    .expect("client session")
}

/// Every device token as it comes and goes (those already live first).
pub fn token_events(
    session: &Session,
) -> troupe_node::zenoh::pubsub::Subscriber<
    troupe_node::zenoh::handlers::FifoChannelHandler<troupe_node::zenoh::sample::Sample>,
> {
    session
        .liveliness()
        .declare_subscriber(troupe_msgs::keys::tokens(None))
        .history(true)
        .wait()
        .expect("liveliness subscriber")
}

/// `["a", "b"]` as owned strings.
pub fn strings(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| (*s).to_owned()).collect()
}
