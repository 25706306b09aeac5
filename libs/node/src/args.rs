//! The Zenoh flags every `troupe` process shares, and how they become a session.

use std::path::PathBuf;
use std::time::Duration;

use clap::{Args, ValueEnum};
use zenoh::{Config, Session, Wait};

use crate::error::{NodeError, Result};

/// Where a process finds its router when nothing else is said: the embedded
/// router of `troupe launch`, or `troupe router` on this host.
pub const DEFAULT_ROUTER: &str = "tcp/127.0.0.1:7447";

/// Where a peer listens when its router is on this host and nothing else
/// is said: loopback, on a port of the system's choosing.
const LOOPBACK_ANY: &str = "tcp/127.0.0.1:0";

/// Whether a Zenoh endpoint (`tcp/127.0.0.1:7447`, `tls/localhost:7447`,
/// `tcp/[::1]:7447`, `unixsock-stream/…`) is on this host: a loopback
/// address, `localhost`, or a Unix socket.
fn on_this_host(endpoint: &str) -> bool {
    let Some((proto, rest)) = endpoint.split_once('/') else {
        return false;
    };
    if proto.starts_with("unixsock") {
        return true;
    }
    // The address, without Zenoh's `?metadata` or `#config`.
    let addr = rest.split(['?', '#']).next().unwrap_or(rest);
    let host = match addr.rsplit_once(':') {
        Some((host, _port)) => host,
        None => addr,
    };
    let host = host.trim_start_matches('[').trim_end_matches(']');
    host.eq_ignore_ascii_case("localhost")
        || host
            .parse::<std::net::IpAddr>()
            .is_ok_and(|ip| ip.is_loopback())
}

/// Zenoh's session modes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Mode {
    /// Talks to other peers directly and through routers (default).
    Peer,
    /// Talks only through the router it connects to.
    Client,
    /// Routes for others (what `troupe router` runs).
    Router,
}

impl Mode {
    fn as_str(self) -> &'static str {
        match self {
            Mode::Peer => "peer",
            Mode::Client => "client",
            Mode::Router => "router",
        }
    }
}

/// Flags shared by every command that opens a Zenoh session.
#[derive(Debug, Clone, Default, Args)]
pub struct ZenohArgs {
    /// Endpoint to connect to (repeatable), e.g. `tcp/10.0.0.2:7447`.
    /// Default: the local router at tcp/127.0.0.1:7447, unless --zenoh-config says otherwise.
    #[arg(long, value_name = "ENDPOINT", global = true)]
    pub connect: Vec<String>,

    /// Endpoint to listen on (repeatable), e.g. `tcp/127.0.0.1:0`.
    #[arg(long, value_name = "ENDPOINT", global = true)]
    pub listen: Vec<String>,

    /// Session mode.
    #[arg(long, value_enum, global = true)]
    pub mode: Option<Mode>,

    /// Prefix every key with this namespace: isolates a fleet or a test on a shared network.
    #[arg(long, value_name = "NS", global = true, env = "TROUPE_NAMESPACE")]
    pub namespace: Option<String>,

    /// A Zenoh JSON5 config file (TLS, authentication, access control…);
    /// the flags above override it.
    #[arg(long, value_name = "FILE", global = true)]
    pub zenoh_config: Option<PathBuf>,

    /// Turn off multicast scouting: find others only through --connect
    /// (the default unless a --zenoh-config file turns it on; kept for
    /// scripts and compose files that say it).
    #[arg(long, global = true, conflicts_with = "multicast")]
    pub no_multicast: bool,

    /// Scout for Zenoh peers and routers by UDP multicast on the LAN, as
    /// Zenoh does by default. Off unless asked: the router answers for
    /// every process of a stack, and nothing of it leaks onto the LAN.
    #[arg(long, global = true)]
    pub multicast: bool,

    /// Keep trying the --connect endpoints until they answer, at start-up and
    /// whenever a link drops (every 0.25 s, backing off to 1 s), instead of
    /// failing when no router is up yet: for containers and fleets, where
    /// start order is not guaranteed and a router may restart.
    #[arg(long, global = true)]
    pub reconnect: bool,

    /// Seconds of silence after which a link's other end counts as gone and
    /// its devices leave (Zenoh's lease; default 10). Keep-alives go out
    /// four times per lease.
    #[arg(long, value_name = "SECS", global = true, value_parser = crate::args::seconds)]
    pub lease: Option<f64>,

    /// Send every sample through the network, even to a process on this
    /// host. By default a sample of 3 KB or more (a map, a camera frame)
    /// goes to a process on the same host through shared memory, a 1 MB
    /// frame in a third of the time (ARCHITECTURE.md, "Big samples").
    #[arg(long, global = true)]
    pub no_shm: bool,

    /// Microseconds a node's thread polls for its next sample, reply or
    /// command before it sleeps (default 0: it sleeps at once). A thread
    /// that sleeps takes tens of microseconds to wake, on a 2-core host
    /// most of a round trip; one that polls answers a reply that comes
    /// within this time at once, at the price of its core, busy that long
    /// after each message (ARCHITECTURE.md, "What a hop costs"). `troupe
    /// bench latency`'s reader polls as long. At most 1,000,000 (1 s).
    #[arg(long, value_name = "MICROSECONDS", global = true, default_value_t = 0,
          value_parser = clap::value_parser!(u64).range(0..=1_000_000))]
    pub spin: u64,
}

/// How often `--reconnect` retries: Zenoh's `connect/retry`, in milliseconds.
const RECONNECT_RETRY: &str =
    r#"{"period_init_ms":250,"period_max_ms":1000,"period_increase_factor":2}"#;

impl ZenohArgs {
    /// The Zenoh config these flags describe, in `default_mode` unless --mode says otherwise.
    ///
    /// # Errors
    ///
    /// [`NodeError::Config`] naming the flag or file that Zenoh rejected.
    pub fn config(&self, default_mode: Mode) -> Result<Config> {
        let bad = |what: String| NodeError::config("zenoh", what);
        let mut c = match &self.zenoh_config {
            Some(p) => {
                let mut c = Config::from_file(p).map_err(|e| {
                    bad(format!(
                        "--zenoh-config {}: {}",
                        p.display(),
                        without_location(&e.to_string())
                    ))
                })?;
                beside(&mut c, p)
                    .map_err(|e| bad(format!("--zenoh-config {}: {e}", p.display())))?;
                check_certificates(&c)
                    .map_err(|e| bad(format!("--zenoh-config {}: {e}", p.display())))?;
                c
            }
            None => Config::default(),
        };
        // A file's mode stands unless --mode says otherwise.
        let file_mode = c
            .get_json("mode")
            .ok()
            .and_then(|m| serde_json::from_str::<String>(&m).ok())
            .and_then(|m| Mode::from_str(&m, true).ok());
        let mode = self.mode.or(file_mode).unwrap_or(default_mode);
        set(&mut c, "mode", json_str(mode.as_str()))?;
        let connect =
            if self.connect.is_empty() && self.zenoh_config.is_none() && mode != Mode::Router {
                vec![DEFAULT_ROUTER.to_owned()]
            } else {
                self.connect.clone()
            };
        // Multicast scouting: off unless asked for (or a config file turns
        // it on), so that a stack on this host stays off the LAN.
        // (`None`: as the file has it.)
        let multicast = if self.multicast {
            Some(true)
        } else if self.no_multicast || self.zenoh_config.is_none() {
            Some(false)
        } else {
            None
        };
        if !connect.is_empty() {
            set(&mut c, "connect/endpoints", json_list(&connect))?;
        } else if multicast == Some(false) && self.zenoh_config.is_none() {
            // Nobody to scout for or connect to: Zenoh's start-up wait
            // (500 ms for a router) would only delay the first node.
            set(&mut c, "scouting/delay", "0".into())?;
        }
        if !self.listen.is_empty() {
            set(&mut c, "listen/endpoints", json_list(&self.listen))?;
        } else if mode == Mode::Peer
            && self.zenoh_config.is_none()
            && connect.iter().all(|e| on_this_host(e))
        {
            // A peer listens for the peers its router tells it of (Zenoh's
            // default: on every interface); when that router is on this
            // host, so are they, and loopback will do.
            set(
                &mut c,
                "listen/endpoints",
                json_list(&[LOOPBACK_ANY.into()]),
            )?;
        }
        if let Some(on) = multicast {
            set(&mut c, "scouting/multicast/enabled", on.to_string())?;
        }
        if multicast == Some(false) {
            // Without multicast there is nothing to scout: don't wait for it.
            set(
                &mut c,
                "open/return_conditions/connect_scouted",
                "false".into(),
            )?;
        }
        if let Some(ns) = &self.namespace {
            set(&mut c, "namespace", json_str(ns))?;
        }
        // A simulator step is one burst of every device's sample (2.7 MB for
        // 100 Pioneers): Zenoh's default data queue (2 batches, 1 ms before
        // dropping) loses 12% of it on the way to a recorder, 16 batches and
        // 10 ms lose 1.3% (ARCHITECTURE.md, "Logs"). A config file that sets
        // other values keeps them.
        for (key, zenoh_default, ours) in [
            ("transport/link/tx/queue/size/data", "2", "16"),
            (
                "transport/link/tx/queue/congestion_control/drop/wait_before_drop",
                "1000",
                "10000",
            ),
        ] {
            if c.get_json(key).is_ok_and(|v| v == zenoh_default) {
                set(&mut c, key, ours.into())?;
            }
        }
        if self.reconnect {
            // Zenoh's client gives up at once by default (timeout 0, exit on
            // failure); here every mode waits forever and retries quickly.
            set(
                &mut c,
                "connect/timeout_ms",
                r#"{"router":-1,"peer":-1,"client":-1}"#.into(),
            )?;
            set(&mut c, "connect/exit_on_failure", "false".into())?;
            set(&mut c, "connect/retry", RECONNECT_RETRY.into())?;
        }
        if self.no_shm {
            set(&mut c, "transport/shared_memory/enabled", "false".into())?;
        }
        if let Some(secs) = self.lease {
            if !(secs.is_finite() && (0.1..=3600.0).contains(&secs)) {
                return Err(bad(format!(
                    "--lease {secs}: expected seconds between 0.1 and 3600"
                )));
            }
            set(
                &mut c,
                "transport/link/tx/lease",
                format!("{}", (secs * 1000.0).round() as u64),
            )?;
        }
        Ok(c)
    }

    /// Opens a session in `default_mode` (unless --mode says otherwise).
    ///
    /// # Errors
    ///
    /// [`NodeError::Zenoh`] when the session cannot be opened (a listen address
    /// in use, a bad config).
    pub fn open(&self, default_mode: Mode) -> Result<Session> {
        self.open_config(self.config(default_mode)?)
    }

    /// Opens a session on `config` (this session's, from
    /// [`ZenohArgs::config`]), a refused link said as what to do.
    fn open_config(&self, config: Config) -> Result<Session> {
        let refused = Refused::of(&config);
        if self.reconnect && config.get_json("mode").is_ok_and(|m| m == r#""client""#) {
            // A client's open now blocks until its router answers.
            tracing::info!(
                "joining the router at {} (--reconnect: waiting until it answers)",
                refused.endpoints
            );
        }
        refused.explain(zenoh::open(config).wait())
    }

    /// [`ZenohArgs::open`], its samples stamped by the session's clock (HLC
    /// timestamps): what rmw_zenoh's sessions do, and what its subscribers
    /// of transient-local topics order the samples they recover by.
    ///
    /// # Errors
    ///
    /// As [`ZenohArgs::open`].
    pub fn open_timestamped(&self, default_mode: Mode) -> Result<Session> {
        let mut config = self.config(default_mode)?;
        set(&mut config, "timestamping/enabled", "true".into())?;
        self.open_config(config)
    }

    /// A session that is a peer unless `--mode` says otherwise, but needs
    /// its router as a client does: without `--reconnect`, opening fails
    /// when no `--connect` endpoint answers (a peer's would go on alone,
    /// hearing nothing). For tools that take much data (`troupe record`): a
    /// peer takes it from the publishers directly where it can reach them,
    /// not through the router's queues.
    ///
    /// # Errors
    ///
    /// As [`ZenohArgs::open`].
    pub fn open_peer(&self) -> Result<Session> {
        let mut config = self.config(Mode::Peer)?;
        if !self.reconnect {
            set(
                &mut config,
                "connect/timeout_ms",
                r#"{"router":-1,"peer":0,"client":0}"#.into(),
            )?;
            set(
                &mut config,
                "connect/exit_on_failure",
                r#"{"router":false,"peer":true,"client":true}"#.into(),
            )?;
        }
        self.open_config(config)
    }

    /// [`ZenohArgs::open`] (or, for `Mode::Peer`, [`ZenohArgs::open_peer`])
    /// on a thread of its own, as a future: with `--reconnect` an open
    /// blocks until its router answers, and a caller can race this against
    /// a signal (the thread is left behind).
    pub fn open_in_background(
        &self,
        default_mode: Mode,
    ) -> impl std::future::Future<Output = Result<Session>> {
        let (tx, rx) = tokio::sync::oneshot::channel();
        let me = self.clone();
        std::thread::spawn(move || {
            let _ = tx.send(match default_mode {
                Mode::Peer => me.open_peer(),
                mode => me.open(mode),
            });
        });
        async move {
            rx.await.unwrap_or_else(|_| {
                Err(NodeError::config(
                    "zenoh",
                    "the thread opening the session died",
                ))
            })
        }
    }

    /// The flags to hand a child process so it joins the same network.
    pub fn to_child_args(&self) -> Vec<String> {
        let mut v = Vec::new();
        for e in &self.connect {
            v.extend(["--connect".to_owned(), e.clone()]);
        }
        if let Some(ns) = &self.namespace {
            v.extend(["--namespace".to_owned(), ns.clone()]);
        }
        if let Some(p) = &self.zenoh_config {
            v.extend(["--zenoh-config".to_owned(), p.display().to_string()]);
        }
        if self.no_multicast {
            v.push("--no-multicast".to_owned());
        }
        if self.multicast {
            v.push("--multicast".to_owned());
        }
        if let Some(m) = self.mode {
            v.extend(["--mode".to_owned(), m.as_str().to_owned()]);
        }
        if self.reconnect {
            v.push("--reconnect".to_owned());
        }
        if let Some(l) = self.lease {
            v.extend(["--lease".to_owned(), l.to_string()]);
        }
        if self.no_shm {
            v.push("--no-shm".to_owned());
        }
        if self.spin > 0 {
            v.extend(["--spin".to_owned(), self.spin.to_string()]);
        }
        v
    }

    /// How long a node's thread polls before it sleeps (`--spin`).
    pub fn spin(&self) -> Duration {
        Duration::from_micros(self.spin)
    }
}

/// The settings of a Zenoh config that name files.
const FILE_KEYS: [&str; 9] = [
    "transport/auth/usrpwd/dictionary_file",
    "transport/auth/pubkey/public_key_file",
    "transport/auth/pubkey/private_key_file",
    "transport/auth/pubkey/known_keys_file",
    "transport/link/tls/root_ca_certificate",
    "transport/link/tls/listen_private_key",
    "transport/link/tls/listen_certificate",
    "transport/link/tls/connect_private_key",
    "transport/link/tls/connect_certificate",
];

/// Takes the relative file names in a config from the config's own
/// directory (Zenoh takes them from the working directory, which differs
/// between a shell, a supervisor's child and a container), and checks
/// that each can be read: Zenoh's own error would not name the file.
fn beside(c: &mut Config, file: &std::path::Path) -> std::result::Result<(), ConfigFileError> {
    let dir = file.parent().unwrap_or(std::path::Path::new(""));
    for key in FILE_KEYS {
        let Some(name) = c
            .get_json(key)
            .ok()
            .and_then(|v| serde_json::from_str::<String>(&v).ok())
        else {
            continue;
        };
        let full = dir.join(&name);
        if let Err(source) = std::fs::File::open(&full) {
            return Err(ConfigFileError::Unreadable {
                key: (*key).to_owned(),
                path: full.display().to_string(),
                source,
            });
        }
        if full.as_os_str() != name.as_str() {
            let full = full.display().to_string();
            c.insert_json5(key, &json_str(&full))
                .map_err(|e| ConfigFileError::Rewrite {
                    key: (*key).to_owned(),
                    value: full,
                    reason: e.to_string(),
                })?;
        }
    }
    Ok(())
}

/// What is wrong in a Zenoh config file, found before Zenoh would fail
/// on it without naming the file.
#[derive(Debug, thiserror::Error)]
pub enum ConfigFileError {
    /// A file it names cannot be read.
    #[error("{key} `{path}`: {source}")]
    Unreadable {
        /// The config key (or certificate field) naming the file.
        key: String,
        /// The file, as opened.
        path: String,
        /// Why it cannot be read.
        source: std::io::Error,
    },
    /// A file's name, taken from the config's directory, could not be put back.
    #[error("{key} = {value}: {reason}")]
    Rewrite {
        /// The config key.
        key: String,
        /// The full path.
        value: String,
        /// Zenoh's reason.
        reason: String,
    },
    /// A `..._base64` certificate field is not base64.
    #[error("{name}_base64 is not base64: {reason}")]
    NotBase64 {
        /// The certificate field.
        name: String,
        /// The decoder's reason.
        reason: String,
    },
    /// A certificate field holds something else.
    #[error("{name} is not {what}: {reason}")]
    NotCertificate {
        /// The certificate field.
        name: String,
        /// What it should be.
        what: &'static str,
        /// The parser's reason.
        reason: String,
    },
    /// The authority's certificate is out of its validity.
    #[error("the authority's certificate ({subject}) {dates}")]
    AuthorityDates {
        /// Its subject.
        subject: String,
        /// What is wrong with its dates.
        dates: String,
    },
    /// This host's certificate is out of its validity.
    #[error("this host's certificate ({subject}) {dates}: make new ones with `troupe fleet-keys`")]
    HostDates {
        /// Its subject.
        subject: String,
        /// What is wrong with its dates.
        dates: String,
    },
    /// This host's certificate comes from another authority.
    #[error(
        "this host's certificate ({subject}) was issued by `{issuer}`, not by this config's \
         authority `{authority}`: both must come from the same `troupe fleet-keys`"
    )]
    WrongIssuer {
        /// Its subject.
        subject: String,
        /// Who issued it.
        issuer: String,
        /// The config's authority.
        authority: String,
    },
}

/// What is wrong with the certificates a Zenoh config names: a file that is
/// not there, a certificate out of its validity, one not issued by the
/// authority beside it. Zenoh itself would only fail to make a link.
fn check_certificates(c: &Config) -> std::result::Result<(), ConfigFileError> {
    use base64::Engine as _;
    let field = |k: &str| -> Option<String> {
        let v = c.get_json(&format!("transport/link/tls/{k}")).ok()?;
        serde_json::from_str::<String>(&v).ok()
    };
    // A certificate, by its field (a path, or the PEM text in base64).
    let pem = |name: &str| -> std::result::Result<Option<Vec<u8>>, ConfigFileError> {
        if let Some(path) = field(name) {
            return std::fs::read(&path)
                .map(Some)
                .map_err(|source| ConfigFileError::Unreadable {
                    key: name.to_owned(),
                    path,
                    source,
                });
        }
        match field(&format!("{name}_base64")) {
            None => Ok(None),
            Some(b) => base64::engine::general_purpose::STANDARD
                .decode(b.trim())
                .map(Some)
                .map_err(|e| ConfigFileError::NotBase64 {
                    name: name.to_owned(),
                    reason: e.to_string(),
                }),
        }
    };
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_secs()).unwrap_or(i64::MAX));
    // Subject, issuer, and what is wrong with its dates, if anything.
    let read = |name: &str,
                bytes: &[u8]|
     -> std::result::Result<(String, String, Option<String>), ConfigFileError> {
        let not = |what: &'static str, reason: String| ConfigFileError::NotCertificate {
            name: name.to_owned(),
            what,
            reason,
        };
        let (_, p) = x509_parser::pem::parse_x509_pem(bytes)
            .map_err(|e| not("a PEM certificate", e.to_string()))?;
        let cert = p
            .parse_x509()
            .map_err(|e| not("an X.509 certificate", e.to_string()))?;
        let v = cert.validity();
        let dates = if v.not_after.timestamp() < now {
            Some(format!("expired on {}", v.not_after))
        } else if v.not_before.timestamp() > now {
            Some(format!("is not valid before {}", v.not_before))
        } else {
            None
        };
        Ok((cert.subject().to_string(), cert.issuer().to_string(), dates))
    };
    let ca = match pem("root_ca_certificate")? {
        Some(b) => Some(read("root_ca_certificate", &b)?),
        None => None,
    };
    if let Some((subject, _, Some(dates))) = ca.clone() {
        return Err(ConfigFileError::AuthorityDates { subject, dates });
    }
    for name in ["connect_certificate", "listen_certificate"] {
        let Some(bytes) = pem(name)? else { continue };
        let (subject, issuer, dates) = read(name, &bytes)?;
        if let Some(dates) = dates {
            return Err(ConfigFileError::HostDates { subject, dates });
        }
        if let Some((authority, _, _)) = &ca {
            if issuer != *authority {
                return Err(ConfigFileError::WrongIssuer {
                    subject,
                    issuer,
                    authority: authority.clone(),
                });
            }
        }
    }
    Ok(())
}

/// What to say when a session cannot reach its router.
struct Refused {
    endpoints: String,
    tls: bool,
    certificates: bool,
}

impl Refused {
    fn of(config: &Config) -> Refused {
        let list: Vec<String> = config
            .get_json("connect/endpoints")
            .ok()
            .and_then(|j| serde_json::from_str(&j).ok())
            .unwrap_or_default();
        let has = |k: &str| {
            config
                .get_json(&format!("transport/link/tls/{k}"))
                .is_ok_and(|v| v != "null")
        };
        Refused {
            tls: list.iter().any(|e| e.starts_with("tls/")),
            certificates: has("connect_certificate") || has("connect_certificate_base64"),
            endpoints: if list.is_empty() {
                DEFAULT_ROUTER.to_owned()
            } else {
                list.join(", ")
            },
        }
    }

    /// What is plainly wrong with the endpoints, seen from this machine: a
    /// name that does not resolve here, or a plain-TCP endpoint where
    /// something listens that is no plain Zenoh router (a fleet's TLS one).
    fn unreachable_why(&self) -> Option<String> {
        use std::net::ToSocketAddrs;
        for ep in self.endpoints.split(", ") {
            let Some((proto, addr)) = ep.split_once('/') else {
                continue;
            };
            let Ok(mut addrs) = addr.to_socket_addrs() else {
                let host = addr.rsplit_once(':').map_or(addr, |(h, _)| h);
                return Some(format!(
                    "the name `{host}` in {ep} does not resolve on this machine: on the router's own \
                     machine give --connect {proto}/localhost:{port}, elsewhere its address; a fleet's \
                     configs name the router given to `troupe fleet-keys --router NAME`",
                    port = addr.rsplit_once(':').map_or("7447", |(_, p)| p)
                ));
            };
            let listening = addrs.next().is_some_and(|a| {
                std::net::TcpStream::connect_timeout(&a, std::time::Duration::from_millis(300))
                    .is_ok()
            });
            if proto == "tcp" && listening {
                return Some(format!(
                    "something listens at {ep} but does not answer as a plain-TCP Zenoh router: a \
                     secured fleet's router takes TLS only (join with --zenoh-config keys/NAME.json5 \
                     and --connect tls/{addr})"
                ));
            }
        }
        None
    }

    /// Zenoh's own words name a source file; say what to do instead.
    fn explain(self, r: zenoh::Result<Session>) -> Result<Session> {
        r.map_err(|e| {
            // (A client's words, and a peer's that must reach its endpoints.)
            let text = e.to_string();
            if !text.contains("Unable to connect to any of") && !text.contains("Can not create a new")
            {
                return NodeError::zenoh("opening the session", e);
            }
            if let Some(why) = self.unreachable_why() {
                return NodeError::Unreachable(why);
            }
            if self.tls {
                NodeError::TlsRefused {
                    endpoints: self.endpoints,
                    hint: if self.certificates {
                        ""
                    } else {
                        "; this host has no certificate: --zenoh-config HOST.json5 from `troupe fleet-keys`"
                    },
                }
            } else {
                NodeError::NoRouter {
                    endpoints: self.endpoints,
                }
            }
        })
    }
}

/// Zenoh's error text without the place in Zenoh's sources it came from
/// (` at /…/.cargo/registry/…/lib.rs:1507.`): that path is the build
/// machine's, and means nothing to the person reading the error.
pub fn without_location(text: &str) -> String {
    match text.rfind(" at ") {
        Some(i) if text[i..].contains(".rs:") => text[..i].trim_end().to_owned(),
        _ => text.to_owned(),
    }
}

/// What is wrong with a flag's number, for clap to print (exit 2).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NumberError {
    /// Not a number at all.
    #[error("{0} is not a number")]
    NotANumber(String),
    /// `inf` or `NaN`.
    #[error("{0} is not a finite number")]
    NotFinite(String),
    /// Seconds below zero.
    #[error("{0} is negative: give seconds, 0 or more")]
    Negative(String),
    /// More than [`MAX_SECONDS`].
    #[error("{0} is too long: give at most {MAX_SECONDS} seconds (a year)")]
    TooLong(String),
}

/// A flag's number of seconds (`--grace 2.5`): finite and not negative.
/// Every duration flag of the CLI parses with it, so that `inf`, `NaN`
/// and `-1` are refused with a message (exit 2) rather than panicking
/// where they become a `Duration`.
///
/// # Errors
///
/// What is wrong with `text`.
pub fn seconds(text: &str) -> std::result::Result<f64, NumberError> {
    let v = finite(text)?;
    if v < 0.0 {
        return Err(NumberError::Negative(text.to_owned()));
    }
    if v > MAX_SECONDS {
        return Err(NumberError::TooLong(text.to_owned()));
    }
    Ok(v)
}

/// The longest duration a flag takes: a year.
pub const MAX_SECONDS: f64 = 365.0 * 24.0 * 3600.0;

/// A flag's number (a rate, a probability, a speed-up): finite; `inf` and
/// `NaN` are refused. Ranges of their own are checked where the value is
/// used.
///
/// # Errors
///
/// What is wrong with `text`.
pub fn finite(text: &str) -> std::result::Result<f64, NumberError> {
    match text.trim().parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(NumberError::NotFinite(text.to_owned())),
        Err(_) => Err(NumberError::NotANumber(text.to_owned())),
    }
}

/// The endpoints a session listens on (e.g. a router opened on port 0 reports
/// its real port here), as `--connect` takes them.
pub fn locators(session: &Session) -> Vec<String> {
    session
        .info()
        .locators()
        .wait()
        .iter()
        .map(ToString::to_string)
        .collect()
}

/// Sets `key` of `c` to `json`, a refusal named as a config error.
fn set(c: &mut Config, key: &str, json: String) -> Result<()> {
    c.insert_json5(key, &json)
        .map_err(|e| NodeError::config("zenoh", format!("{key} = {json}: {e}")))
}

fn json_str(s: &str) -> String {
    serde_json::Value::String(s.to_owned()).to_string()
}

fn json_list(v: &[String]) -> String {
    serde_json::Value::from(v.to_vec()).to_string()
}

/// Starts logging to stderr: `filter` (or `RUST_LOG`, or `info`), Zenoh kept quiet.
pub fn init_logging(filter: Option<&str>) {
    use tracing_subscriber::EnvFilter;
    let asked = filter
        .map(str::to_owned)
        .or_else(|| std::env::var("RUST_LOG").ok());
    // Zenoh's own lines (link warnings naming its source files, "Unknown
    // interest" at start) are for who asks: Troupe says what went wrong in
    // its own words. A filter given (--log, $RUST_LOG) shows Zenoh's
    // warnings too, all of it when it names zenoh.
    let zenoh_level = if asked.is_some() { "warn" } else { "off" };
    let spec = asked.unwrap_or_else(|| "info".to_owned());
    let spec = if spec.contains("zenoh") {
        spec
    } else {
        let crates = [
            "zenoh",
            "zenoh_transport",
            "zenoh_link_tcp",
            "zenoh_link_tls",
            "zenoh_link_commons",
            "zenoh_config",
            "zenoh_shm",
        ];
        let quiet: Vec<String> = crates
            .iter()
            .map(|c| format!("{c}={zenoh_level}"))
            .collect();
        format!("{spec},{}", quiet.join(","))
    };
    let filter = EnvFilter::try_new(&spec).unwrap_or_else(|_| EnvFilter::new("info"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_target(false)
        // A closed stderr (a dead launcher's pipe) must not panic the logger.
        .log_internal_errors(false)
        .try_init();
}

/// The viewer a Zenoh config joins a fleet as (`troupe fleet-keys
/// --viewers`), if it is one: the name the config's `metadata` gives.
pub fn viewer_of(metadata: &serde_json::Value) -> Option<String> {
    let me = metadata.get("troupe")?;
    if me.get("kind")? != "viewer" {
        return None;
    }
    me.get("identity")?.as_str().map(str::to_owned)
}

#[cfg(test)]
mod tests {
    #[test]
    fn zenoh_s_source_locations_are_left_out() {
        assert_eq!(
            super::without_location("No such file or directory (os error 2) at /root/.cargo/registry/src/x/zenoh-config/src/lib.rs:1507."),
            "No such file or directory (os error 2)"
        );
        assert_eq!(super::without_location("meet at noon"), "meet at noon");
    }

    use super::*;

    #[test]
    fn flags_reach_the_zenoh_config() {
        let a = ZenohArgs {
            connect: vec!["tcp/127.0.0.1:9".into()],
            namespace: Some("t1".into()),
            no_multicast: true,
            ..Default::default()
        };
        let c = a.config(Mode::Peer).unwrap();
        assert_eq!(
            c.get_json("connect/endpoints").unwrap(),
            r#"["tcp/127.0.0.1:9"]"#
        );
        assert_eq!(c.get_json("namespace").unwrap(), r#""t1""#);
        assert_eq!(c.get_json("scouting/multicast/enabled").unwrap(), "false");
        let d = ZenohArgs::default().config(Mode::Peer).unwrap();
        assert_eq!(
            d.get_json("connect/endpoints").unwrap(),
            format!("[\"{DEFAULT_ROUTER}\"]")
        );
    }

    #[test]
    fn nothing_scouts_the_lan_and_a_peer_of_a_local_router_listens_on_loopback() {
        let listen = |c: &Config| c.get_json("listen/endpoints").unwrap();
        let multicast = |c: &Config| c.get_json("scouting/multicast/enabled").unwrap();
        // No flags: the default router, on this host.
        let d = ZenohArgs::default().config(Mode::Peer).unwrap();
        assert_eq!(multicast(&d), "false");
        assert_eq!(listen(&d), r#"["tcp/127.0.0.1:0"]"#);
        let client = ZenohArgs::default().config(Mode::Client).unwrap();
        assert_eq!(multicast(&client), "false");
        assert_ne!(
            listen(&client),
            listen(&d),
            "a client is left as Zenoh has it"
        );
        // A router elsewhere: its other peers must reach this one.
        let remote = ZenohArgs {
            connect: vec!["tcp/10.1.2.3:7447".into()],
            ..Default::default()
        };
        let r = remote.config(Mode::Peer).unwrap();
        assert_ne!(listen(&r), listen(&d));
        assert_eq!(multicast(&r), "false");
        // Asked for: multicast; said: the listener.
        let asked = ZenohArgs {
            multicast: true,
            listen: vec!["tcp/127.0.0.1:7000".into()],
            ..Default::default()
        };
        let a = asked.config(Mode::Peer).unwrap();
        assert_eq!(multicast(&a), "true");
        assert_eq!(listen(&a), r#"["tcp/127.0.0.1:7000"]"#);
        assert!(asked.to_child_args().contains(&"--multicast".to_owned()));
        for (endpoint, here) in [
            ("tcp/127.0.0.1:7447", true),
            ("tcp/localhost:7447", true),
            ("tls/LOCALHOST:7447", true),
            ("tcp/[::1]:7447", true),
            ("tcp/127.0.0.1:7447#iface=lo", true),
            ("unixsock-stream//tmp/zenoh.sock", true),
            ("tcp/10.1.2.3:7447", false),
            ("tcp/router:7447", false),
            ("tcp/[::]:7447", false),
            ("tcp", false),
        ] {
            assert_eq!(on_this_host(endpoint), here, "{endpoint}");
        }
    }

    #[test]
    fn a_peer_beside_a_router_on_this_host_is_reachable_on_loopback_only() {
        let router = ZenohArgs {
            listen: vec![LOOPBACK_ANY.into()],
            ..Default::default()
        }
        .open(Mode::Router)
        .unwrap();
        let endpoint = locators(&router).into_iter().next().unwrap();
        let peer = ZenohArgs {
            connect: vec![endpoint],
            ..Default::default()
        }
        .open(Mode::Peer)
        .unwrap();
        let at = locators(&peer);
        assert!(
            !at.is_empty() && at.iter().all(|l| l.starts_with("tcp/127.0.0.1:")),
            "{at:?}"
        );
    }

    #[test]
    fn no_shm_turns_shared_memory_off_here_and_in_the_children() {
        let on = ZenohArgs::default().config(Mode::Peer).unwrap();
        assert_eq!(
            on.get_json("transport/shared_memory/enabled").unwrap(),
            "true"
        );
        let off = ZenohArgs {
            no_shm: true,
            ..Default::default()
        };
        let c = off.config(Mode::Peer).unwrap();
        assert_eq!(
            c.get_json("transport/shared_memory/enabled").unwrap(),
            "false"
        );
        assert!(off.to_child_args().contains(&"--no-shm".to_owned()));
    }

    #[test]
    fn spin_reaches_the_children_and_only_when_asked() {
        assert_eq!(ZenohArgs::default().spin(), Duration::ZERO);
        assert!(!ZenohArgs::default()
            .to_child_args()
            .contains(&"--spin".to_owned()));
        let a = ZenohArgs {
            spin: 250,
            ..Default::default()
        };
        assert_eq!(a.spin(), Duration::from_micros(250));
        let args = a.to_child_args();
        let at = args.iter().position(|s| s == "--spin").expect("--spin");
        assert_eq!(args[at + 1], "250");
    }

    #[test]
    fn reconnect_and_lease_reach_the_zenoh_config_and_the_children() {
        let a = ZenohArgs {
            connect: vec!["tcp/router:7447".into()],
            reconnect: true,
            lease: Some(3.0),
            ..Default::default()
        };
        let c = a.config(Mode::Client).unwrap();
        assert_eq!(c.get_json("connect/exit_on_failure").unwrap(), "false");
        assert!(c
            .get_json("connect/timeout_ms")
            .unwrap()
            .contains(r#""client":-1"#));
        assert!(c
            .get_json("connect/retry")
            .unwrap()
            .contains(r#""period_init_ms":250"#));
        assert_eq!(c.get_json("transport/link/tx/lease").unwrap(), "3000");
        let child = ZenohArgs {
            mode: Some(Mode::Client),
            ..a.clone()
        }
        .to_child_args();
        assert!(child.contains(&"--reconnect".to_owned()), "{child:?}");
        assert!(
            child.windows(2).any(|w| w == ["--mode", "client"]),
            "{child:?}"
        );
        assert!(child.windows(2).any(|w| w == ["--lease", "3"]), "{child:?}");
        let bad = ZenohArgs {
            lease: Some(0.0),
            ..Default::default()
        };
        let e = bad.config(Mode::Peer).unwrap_err().to_string();
        assert!(e.contains("--lease 0"), "{e}");
    }

    #[test]
    fn a_client_with_no_router_is_told_how_to_get_one() {
        // A port nothing listens on: bound, then let go.
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .unwrap()
            .port();
        let args = ZenohArgs {
            connect: vec![format!("tcp/127.0.0.1:{port}")],
            no_multicast: true,
            ..Default::default()
        };
        let e = args.open(Mode::Client).err().unwrap().to_string();
        assert!(
            e.contains(&format!("no Zenoh router answers at tcp/127.0.0.1:{port}")),
            "{e}"
        );
        assert!(e.contains("troupe router"), "{e}");
    }

    #[test]
    fn a_bad_endpoint_or_namespace_names_the_flag() {
        let a = ZenohArgs {
            namespace: Some("a/*".into()),
            ..Default::default()
        };
        let e = a.config(Mode::Peer).unwrap_err().to_string();
        assert!(e.contains("namespace"), "{e}");
        let a = ZenohArgs {
            zenoh_config: Some("/nonexistent/z.json5".into()),
            ..Default::default()
        };
        let e = a.config(Mode::Peer).unwrap_err().to_string();
        assert!(e.contains("/nonexistent/z.json5"), "{e}");
    }

    #[test]
    fn a_config_s_files_are_taken_from_its_directory_and_a_missing_one_is_named() {
        let dir = std::env::temp_dir().join(format!("troupe-beside-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let cfg = dir.join("router.json5");
        std::fs::write(
            &cfg,
            r#"{ transport: { auth: { usrpwd: { dictionary_file: "passwords" } } } }"#,
        )
        .unwrap();
        let args = ZenohArgs {
            zenoh_config: Some(cfg.clone()),
            ..Default::default()
        };
        let e = args.config(Mode::Router).unwrap_err().to_string();
        let want = dir.join("passwords").display().to_string();
        assert!(e.contains(&format!("dictionary_file `{want}`")), "{e}");
        std::fs::write(dir.join("passwords"), "a:b\n").unwrap();
        let c = args.config(Mode::Router).unwrap();
        assert_eq!(
            c.get_json("transport/auth/usrpwd/dictionary_file").unwrap(),
            json_str(&want)
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
