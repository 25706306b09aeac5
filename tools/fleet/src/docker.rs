//! Containers: `troupe image` builds the one image, `troupe compose` writes
//! a Docker Compose file that runs a plan as a fleet of containers.
//!
//! The image is `FROM scratch` (the machines have no registry to pull a base
//! from): the binary, the shared libraries `ldd` says it loads, a passwd
//! entry for its numeric user, and the sample worlds. The compose file runs
//! a router, one container per host of the plan (each a `troupe launch
//! --host NAME`, its nodes still one process each), and a Player bridge
//! whose ports are published on the host's 127.0.0.1 only.

use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Component, Path, PathBuf};
use std::process::Command;

use anyhow::Context;
use clap::Args;
use troupe_msgs::{keys, Device};

use troupe_launch::catalog::Catalog;
use troupe_launch::plan::{self, Plan};

/// The Dockerfile `troupe image` builds (docker/Dockerfile).
const DOCKERFILE: &str = include_str!("../../../docker/Dockerfile");

/// The image's user and group: numeric, not root.
pub const UID: u32 = 10000;

/// Flags of `troupe image`.
#[derive(Debug, Args)]
pub struct ImageArgs {
    /// The image's name and tag.
    #[arg(
        long,
        short = 't',
        value_name = "NAME:TAG",
        default_value = "troupe:latest"
    )]
    pub tag: String,
    /// Directory to stage the build context in (its rootfs/ and Dockerfile are replaced).
    #[arg(long, value_name = "DIR", default_value = "target/docker")]
    pub context: PathBuf,
    /// The world files, .inc files and bitmaps to put in the image at /worlds.
    #[arg(long, value_name = "DIR", default_value = "worlds")]
    pub worlds: PathBuf,
    /// The binary to put in the image (default: this one).
    #[arg(long, value_name = "FILE")]
    pub binary: Option<PathBuf>,
    /// Stage the context only; build it later with `docker build -t TAG DIR`.
    #[arg(long)]
    pub no_build: bool,
}

/// `troupe image`.
pub fn image(a: ImageArgs) -> anyhow::Result<()> {
    let exe = match &a.binary {
        Some(b) => b.clone(),
        None => std::env::current_exe().context("finding the troupe binary")?,
    };
    if !a.worlds.is_dir() {
        anyhow::bail!(
            "--worlds {}: no such directory (run from the repository's top level, or name the worlds to ship)",
            a.worlds.display()
        );
    }
    let staged = stage(&exe, &a.worlds, &a.context)?;
    let mut err = std::io::stderr().lock();
    writeln!(
        err,
        "staged {} ({} files, {:.1} MB: the binary {:.1} MB, {} libraries {:.1} MB)",
        a.context.display(),
        staged.files,
        mb(staged.bytes),
        mb(staged.binary),
        staged.libs.len(),
        mb(staged.lib_bytes)
    )?;
    drop(err);
    if a.no_build {
        return Ok(());
    }
    // The engine's chatter (the legacy builder's deprecation notice) is
    // shown only when the build fails.
    let out = Command::new("docker")
        .args(["build", "--quiet", "-t", &a.tag])
        .arg(&a.context)
        .output()
        .context("running `docker build` (is Docker installed?)")?;
    if !out.status.success() {
        anyhow::bail!(
            "`docker build -t {} {}` failed ({}): {}",
            a.tag,
            a.context.display(),
            out.status,
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    let size = image_size(&a.tag)?;
    let mut out = std::io::stdout().lock();
    writeln!(out, "troupe image: {} ({:.1} MB)", a.tag, mb(size))?;
    Ok(())
}

fn mb(bytes: u64) -> f64 {
    bytes as f64 / 1e6
}

/// The size Docker reports for an image, in bytes.
pub fn image_size(tag: &str) -> anyhow::Result<u64> {
    let out = Command::new("docker")
        .args(["image", "inspect", "--format", "{{.Size}}", tag])
        .output()
        .context("running `docker image inspect`")?;
    if !out.status.success() {
        anyhow::bail!(
            "docker image inspect {tag}: {}",
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    String::from_utf8_lossy(&out.stdout)
        .trim()
        .parse()
        .with_context(|| format!("docker image inspect {tag}: not a size"))
}

/// What `stage` put in a build context.
#[derive(Debug)]
pub struct Staged {
    /// Files in rootfs/.
    pub files: usize,
    /// Their bytes.
    pub bytes: u64,
    /// The binary's bytes.
    pub binary: u64,
    /// The shared libraries, by their path in the image.
    pub libs: Vec<PathBuf>,
    /// Their bytes.
    pub lib_bytes: u64,
}

/// Stages the build context in `dir`: the Dockerfile and rootfs/ with the
/// binary at /troupe, its shared libraries at the paths the loader finds
/// them, /etc (passwd, group, nsswitch.conf), /tmp and /worlds.
pub fn stage(exe: &Path, worlds: &Path, dir: &Path) -> anyhow::Result<Staged> {
    let rootfs = dir.join("rootfs");
    if rootfs.exists() {
        std::fs::remove_dir_all(&rootfs)
            .with_context(|| format!("clearing {}", rootfs.display()))?;
    }
    std::fs::create_dir_all(&rootfs).with_context(|| format!("creating {}", rootfs.display()))?;
    std::fs::write(dir.join("Dockerfile"), DOCKERFILE)
        .with_context(|| format!("writing {}", dir.join("Dockerfile").display()))?;
    let mut files = 0;
    let mut bytes = 0;
    let bin = rootfs.join("troupe");
    let binary = std::fs::copy(exe, &bin)
        .with_context(|| format!("copying {} into the image", exe.display()))?;
    // Debug sections (line tables) are for backtraces on a developer's
    // machine; function names stay. No `strip`: ship the file as it is.
    let binary = match Command::new("strip")
        .arg("--strip-debug")
        .arg(&bin)
        .status()
    {
        Ok(s) if s.success() => std::fs::metadata(&bin).map(|m| m.len()).unwrap_or(binary),
        _ => binary,
    };
    files += 1;
    bytes += binary;
    let libs = shared_libraries(exe)?;
    let mut lib_bytes = 0;
    for lib in &libs {
        let to = under(&rootfs, lib)?;
        if let Some(p) = to.parent() {
            std::fs::create_dir_all(p)?;
        }
        // fs::copy follows symlinks: the image gets the library itself at the
        // path the loader asks for.
        let n = std::fs::copy(lib, &to)
            .with_context(|| format!("copying {} into the image", lib.display()))?;
        lib_bytes += n;
        files += 1;
    }
    bytes += lib_bytes;
    let etc = rootfs.join("etc");
    std::fs::create_dir_all(&etc)?;
    for (name, text) in [
        (
            "passwd",
            format!("troupe:x:{UID}:{UID}:troupe:/tmp:/troupe\n"),
        ),
        ("group", format!("troupe:x:{UID}:\n")),
        // Compose service names come from Docker's DNS; /etc/hosts first.
        ("nsswitch.conf", "hosts: files dns\n".to_owned()),
    ] {
        std::fs::write(etc.join(name), text)?;
        files += 1;
    }
    let tmp = rootfs.join("tmp");
    std::fs::create_dir_all(&tmp)?;
    set_mode(&tmp, 0o1777)?;
    let (n, b) = copy_tree(worlds, &rootfs.join("worlds"))?;
    files += n;
    bytes += b;
    Ok(Staged {
        files,
        bytes,
        binary,
        libs,
        lib_bytes,
    })
}

fn set_mode(p: &Path, mode: u32) -> anyhow::Result<()> {
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(p, std::fs::Permissions::from_mode(mode))
        .with_context(|| format!("setting the mode of {}", p.display()))
}

/// `path` (absolute) inside `root`.
fn under(root: &Path, path: &Path) -> anyhow::Result<PathBuf> {
    let mut out = root.to_path_buf();
    for c in path.components() {
        match c {
            Component::Normal(n) => out.push(n),
            Component::RootDir => {}
            _ => anyhow::bail!("library path {} is not absolute and plain", path.display()),
        }
    }
    Ok(out)
}

/// Copies a directory tree (files and directories; symlinks followed).
fn copy_tree(from: &Path, to: &Path) -> anyhow::Result<(usize, u64)> {
    std::fs::create_dir_all(to).with_context(|| format!("creating {}", to.display()))?;
    let (mut n, mut b) = (0, 0);
    for e in std::fs::read_dir(from).with_context(|| format!("reading {}", from.display()))? {
        let e = e?;
        let (src, dst) = (e.path(), to.join(e.file_name()));
        if src.is_dir() {
            let (n2, b2) = copy_tree(&src, &dst)?;
            n += n2;
            b += b2;
        } else {
            b += std::fs::copy(&src, &dst).with_context(|| format!("copying {}", src.display()))?;
            n += 1;
        }
    }
    Ok((n, b))
}

/// The shared libraries `exe` loads, as `ldd` resolves them (none for a
/// static binary).
fn shared_libraries(exe: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let out = Command::new("ldd")
        .arg(exe)
        .output()
        .context("running `ldd` to find the binary's shared libraries")?;
    let text = String::from_utf8_lossy(&out.stdout);
    if !out.status.success() {
        if String::from_utf8_lossy(&out.stderr).contains("not a dynamic executable")
            || text.contains("not a dynamic executable")
        {
            return Ok(Vec::new());
        }
        anyhow::bail!(
            "ldd {}: {}",
            exe.display(),
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    parse_ldd(&text)
}

/// The library paths of `ldd`'s output: `libc.so.6 => /lib/…/libc.so.6
/// (0x…)` and the loader's `/lib64/ld-linux-x86-64.so.2 (0x…)`; the
/// kernel's vDSO has no file.
fn parse_ldd(text: &str) -> anyhow::Result<Vec<PathBuf>> {
    let mut libs = Vec::new();
    for line in text.lines().map(str::trim).filter(|l| !l.is_empty()) {
        let path = match line.split_once("=>") {
            Some((name, rest)) => {
                let p = rest.trim().split(" (").next().unwrap_or("").trim();
                if p == "not found" {
                    anyhow::bail!("ldd: {} is not found on this machine", name.trim());
                }
                p
            }
            None => line.split(" (").next().unwrap_or("").trim(),
        };
        if path.starts_with('/') {
            libs.push(PathBuf::from(path));
        }
    }
    Ok(libs)
}

/// Flags of `troupe compose`.
#[derive(Debug, Args)]
pub struct ComposeArgs {
    /// A Player .cfg file or a launch plan.
    pub file: PathBuf,
    /// Robot field (port) for addresses that give none, as `player -p PORT`.
    #[arg(short = 'p', long = "robot", value_name = "PORT", default_value_t = troupe_msgs::DEFAULT_ROBOT)]
    pub robot: u32,
    /// Write the compose file here instead of stdout.
    #[arg(short = 'o', long, value_name = "FILE")]
    pub output: Option<PathBuf>,
    /// The image every service runs (`$TROUPE_IMAGE` overrides it when compose runs).
    #[arg(long, value_name = "NAME:TAG", default_value = "troupe:latest")]
    pub image: String,
    /// The cfg is already in the image, in this directory (e.g. /worlds for
    /// the sample worlds); without it, the cfg's directory is mounted
    /// read-only at /stack.
    #[arg(long, value_name = "DIR")]
    pub in_image: Option<String>,
    /// Run the fleet secured with the configs `troupe fleet-keys DIR` wrote
    /// (mounted read-only at /keys; readable by the image's user 10000): one
    /// per host, `router.json5`, and `bridge.json5` (an operator) for the
    /// bridge and the health checks' router probe.
    #[arg(long, value_name = "DIR")]
    pub secure: Option<PathBuf>,
    /// Zenoh's lease in the fleet, in seconds: how long a cut-off host's
    /// devices stay listed.
    #[arg(long, value_name = "SECS", default_value_t = 3.0, value_parser = troupe_node::args::seconds)]
    pub lease: f64,
    /// Write a Docker Swarm stack instead (`docker stack deploy -c FILE
    /// NAME`): each host of the cfg a service on the nodes labelled
    /// `troupe.host.HOST=true` beside a Zenoh router of its own, the
    /// hosts' routers linked to the fleet's router, an overlay network.
    /// Needs --in-image.
    #[arg(long, conflicts_with = "k8s")]
    pub swarm: bool,
    /// Write Kubernetes manifests instead (`kubectl apply -f FILE`): each
    /// host a Deployment on the nodes labelled `troupe.host/HOST=true`
    /// beside a router of its own, Services for the routers and the Player
    /// ports, readiness probes. Needs --in-image.
    #[arg(long)]
    pub k8s: bool,
}

/// What `troupe compose` writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Target {
    /// A Docker Compose file: one machine.
    Compose,
    /// A Docker Swarm stack.
    Swarm,
    /// Kubernetes manifests.
    K8s,
}

impl ComposeArgs {
    /// What these flags ask for.
    pub fn target(&self) -> Target {
        match (self.swarm, self.k8s) {
            (true, _) => Target::Swarm,
            (_, true) => Target::K8s,
            _ => Target::Compose,
        }
    }
}

/// `troupe compose`.
pub fn compose(a: ComposeArgs, catalog: &Catalog) -> anyhow::Result<()> {
    let text = render(&a, catalog)?;
    match &a.output {
        Some(p) => std::fs::write(p, text).with_context(|| format!("writing {}", p.display()))?,
        None => std::io::stdout().lock().write_all(text.as_bytes())?,
    }
    Ok(())
}

/// The compose file `troupe compose` writes for these flags.
pub fn render(a: &ComposeArgs, catalog: &Catalog) -> anyhow::Result<String> {
    let (plan, warnings) = plan::load(&a.file, a.robot, catalog)?;
    for w in &warnings {
        let _ = writeln!(std::io::stderr(), "warning: {w}");
    }
    let name = a
        .file
        .file_name()
        .and_then(|n| n.to_str())
        .with_context(|| format!("{}: not a file name", a.file.display()))?
        .to_owned();
    let dir = a.file.parent().unwrap_or(Path::new(""));
    // Paths as seen from the compose file's directory.
    let base = a
        .output
        .as_ref()
        .and_then(|o| o.parent())
        .unwrap_or(Path::new(""));
    let host_dir = relative_to(dir, base)?;
    let source = match &a.in_image {
        Some(d) => Source::InImage(format!("{}/{name}", d.trim_end_matches('/'))),
        None => Source::Mounted {
            host_dir: host_dir.clone(),
            file: name.clone(),
        },
    };
    let shown_file = Path::new(&host_dir).join(&name);
    let mut shown = vec![shown_file
        .strip_prefix("./")
        .unwrap_or(&shown_file)
        .display()
        .to_string()];
    if let Some(d) = &a.in_image {
        shown.extend(["--in-image".into(), d.clone()]);
    }
    if a.robot != troupe_msgs::DEFAULT_ROBOT {
        shown.extend(["-p".into(), a.robot.to_string()]);
    }
    if a.image != "troupe:latest" {
        shown.extend(["--image".into(), a.image.clone()]);
    }
    if a.lease != 3.0 {
        shown.extend(["--lease".into(), a.lease.to_string()]);
    }
    match a.target() {
        Target::Compose => {}
        Target::Swarm => shown.push("--swarm".into()),
        Target::K8s => shown.push("--k8s".into()),
    }
    if a.target() != Target::Compose && a.in_image.is_none() {
        anyhow::bail!(
            "{}: a swarm's or a cluster's nodes do not share this machine's files: put the cfg \
             and its worlds in the image (`troupe image --worlds DIR` puts DIR at /worlds) and \
             name its directory there with --in-image (e.g. --in-image /worlds)",
            a.file.display()
        );
    }
    if let Some(o) = a.output.as_ref().and_then(|o| o.file_name()) {
        shown.extend(["-o".into(), o.to_string_lossy().into_owned()]);
    }
    let keys = match &a.secure {
        None => None,
        Some(d) => {
            let rel = relative_to(d, base)?;
            shown.extend(["--secure".into(), rel.trim_start_matches("./").to_owned()]);
            Some((d.clone(), rel))
        }
    };
    let fleet = Fleet {
        plan: &plan,
        source,
        image: a.image.clone(),
        lease: a.lease,
        command: format!("troupe compose {}", shown.join(" ")),
        keys: keys.as_ref().map(|(_, rel)| rel.clone()),
    };
    if let Some((dir, _)) = &keys {
        fleet.check_keys(dir)?;
    }
    match a.target() {
        Target::Compose => fleet.to_yaml(),
        Target::Swarm => crate::orchestrate::swarm(&fleet),
        Target::K8s => crate::orchestrate::k8s(&fleet),
    }
}

/// Where the containers find the cfg.
#[derive(Debug, Clone)]
pub enum Source {
    /// At this path in the image.
    InImage(String),
    /// In a directory of the host (relative to the compose file) mounted at /stack.
    Mounted { host_dir: String, file: String },
}

/// `dir` relative to `base` (both as given, made absolute against the
/// current directory), for a compose file's volume.
fn relative_to(dir: &Path, base: &Path) -> anyhow::Result<String> {
    let cwd = std::env::current_dir()?;
    let abs = |p: &Path| -> PathBuf {
        let p = if p.as_os_str().is_empty() {
            Path::new(".")
        } else {
            p
        };
        let p = cwd.join(p);
        let mut out = PathBuf::new();
        for c in p.components() {
            match c {
                Component::ParentDir => {
                    out.pop();
                }
                Component::CurDir => {}
                c => out.push(c),
            }
        }
        out
    };
    let (d, b) = (abs(dir), abs(base));
    let common = d
        .components()
        .zip(b.components())
        .take_while(|(x, y)| x == y)
        .count();
    if common <= 1 {
        // Nothing in common but the root: the absolute path reads better.
        return Ok(d.display().to_string());
    }
    let mut rel = PathBuf::new();
    for _ in b.components().skip(common) {
        rel.push("..");
    }
    for c in d.components().skip(common) {
        rel.push(c);
    }
    let s = rel.display().to_string();
    Ok(if s.is_empty() {
        ".".into()
    } else if s.starts_with('.') {
        s
    } else {
        format!("./{s}")
    })
}

/// A plan as containers.
pub struct Fleet<'a> {
    /// The plan.
    pub plan: &'a Plan,
    /// Where its cfg is inside the containers.
    pub source: Source,
    /// The image.
    pub image: String,
    /// Zenoh's lease, seconds.
    pub lease: f64,
    /// The command that wrote it, for the header.
    pub command: String,
    /// `--secure`: the directory of the identities' configs, as the compose
    /// file names it.
    pub keys: Option<String>,
}

/// A service of the fleet: the router, one per host (and, on many
/// machines, a router beside each host), the bridge. One model, which the
/// Compose file, the Swarm stack and the Kubernetes manifests each write
/// in their own terms.
pub(crate) struct Service {
    /// Its name: the container's host name, the address others use.
    pub(crate) name: String,
    /// The troupe binary's arguments.
    pub(crate) command: Vec<String>,
    /// Ports published outside the fleet: the variable that overrides the
    /// host port, and the port.
    pub(crate) ports: Vec<(String, u16)>,
    /// `troupe` arguments that succeed once the service is ready.
    pub(crate) health: Vec<String>,
    /// Services that must be healthy first (Compose only).
    pub(crate) depends: Vec<String>,
    /// What it is, for the reader.
    pub(crate) comment: String,
    /// The cfg host whose machines it runs on; `None`: anywhere.
    pub(crate) place: Option<String>,
    /// The port it listens on inside the fleet (a router's 7447).
    pub(crate) listens: Option<u16>,
    /// The identity whose config it reads, under --secure.
    pub(crate) identity: Option<String>,
}

impl Service {
    /// Its health check: `troupe` with these arguments.
    pub(crate) fn health_command(&self) -> Vec<String> {
        let mut v = vec!["/troupe".to_owned()];
        v.extend(self.health.iter().cloned());
        v
    }

    /// A Compose or Swarm service's first keys: what it is, its name, the
    /// image, its host name and command.
    pub(crate) fn write_head(&self, s: &mut String, image: &str) {
        let _ = writeln!(s, "  # {}", self.comment);
        let _ = writeln!(s, "  {}:", self.name);
        let _ = writeln!(s, "    image: ${{TROUPE_IMAGE:-{image}}}");
        let _ = writeln!(s, "    hostname: {}", self.name);
        let _ = writeln!(s, "    command: {}", yaml_list(&self.command));
    }

    /// A Compose or Swarm service's grace period and health check.
    pub(crate) fn write_health(&self, s: &mut String) {
        s.push_str("    stop_grace_period: 10s\n");
        let mut test = vec!["CMD".to_owned()];
        test.extend(self.health_command());
        let _ = writeln!(s, "    healthcheck:\n      test: {}", yaml_list(&test));
        s.push_str(
            "      interval: 1s\n      timeout: 5s\n      retries: 3\n      start_period: 60s\n",
        );
    }
}

/// Where a host's containers reach the fleet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Layout {
    /// Every container is a client of the one router (one machine).
    OneRouter,
    /// Each host has a router of its own on its machine, linked to the
    /// fleet's router: its nodes' traffic among themselves stays on it.
    RouterPerHost,
}

/// The name of the router beside `host`.
pub(crate) fn host_router(host: &str) -> String {
    format!("router-{host}")
}

impl Fleet<'_> {
    /// The hosts of the plan, in the order their first node appears; every
    /// node must have one, or none has and the whole plan is host `stack`.
    fn hosts(&self) -> anyhow::Result<Vec<(String, Vec<Device>)>> {
        let homeless: Vec<&str> = self
            .plan
            .nodes
            .iter()
            .filter(|n| n.host.is_none())
            .map(|n| n.name.as_str())
            .collect();
        let split = homeless.len() < self.plan.nodes.len();
        if split && !homeless.is_empty() {
            anyhow::bail!(
                "some nodes name a host and these do not: {}; give each a host (the first field of a provided address, e.g. \"robot1:6665:laser:0\") or give none",
                homeless.join(", ")
            );
        }
        let mut hosts: Vec<(String, Vec<Device>)> = Vec::new();
        for n in &self.plan.nodes {
            let h = n.host.clone().unwrap_or_else(|| "stack".to_owned());
            check_service_name(&h)?;
            let devices = n
                .provides
                .iter()
                .filter_map(|r| keys::parse_data(&r.device).ok());
            match hosts.iter_mut().find(|(x, _)| *x == h) {
                Some((_, d)) => d.extend(devices),
                None => hosts.push((h, devices.collect())),
            }
        }
        if hosts.iter().any(|(h, _)| h == "router" || h == "bridge") {
            anyhow::bail!(
                "hosts `router` and `bridge` are the fleet's own services: rename that host"
            );
        }
        Ok(hosts)
    }

    /// How `who` joins the fleet: as a client of `router` by name, or
    /// (secured) with its own config, which says the same over TLS.
    fn net(&self, who: &str, router: &str) -> Vec<String> {
        let mut v = match &self.keys {
            None => vec![
                "--connect".to_owned(),
                format!("tcp/{router}:7447"),
                "--mode".to_owned(),
                "client".to_owned(),
                "--no-multicast".to_owned(),
            ],
            Some(_) => vec!["--zenoh-config".to_owned(), format!("/keys/{who}.json5")],
        };
        v.extend([
            "--reconnect".to_owned(),
            "--lease".to_owned(),
            self.lease.to_string(),
        ]);
        v
    }

    /// A health check's way to `router`, as `who`.
    fn probe(&self, who: &str, router: &str) -> Vec<String> {
        match &self.keys {
            None => vec![
                "--connect".to_owned(),
                format!("tcp/{router}:7447"),
                "--no-multicast".to_owned(),
            ],
            Some(_) => vec!["--zenoh-config".to_owned(), format!("/keys/{who}.json5")],
        }
    }

    /// `--secure DIR`: every identity the fleet needs has its config there.
    fn check_keys(&self, dir: &Path) -> anyhow::Result<()> {
        let hosts = self.hosts()?;
        let mut need = vec!["router".to_owned(), "bridge".to_owned()];
        need.extend(hosts.iter().map(|(h, _)| h.clone()));
        let missing: Vec<&String> = need
            .iter()
            .filter(|n| !dir.join(format!("{n}.json5")).is_file())
            .collect();
        if missing.is_empty() {
            return Ok(());
        }
        let specs: Vec<String> = hosts
            .iter()
            .map(|(h, devices)| {
                let mut robots: Vec<u32> = devices.iter().map(|d| d.robot).collect();
                robots.dedup();
                robots.sort_unstable();
                robots.dedup();
                let ports: Vec<String> = robots.iter().map(ToString::to_string).collect();
                format!("{h}:{}", ports.join(":"))
            })
            .collect();
        anyhow::bail!(
            "--secure {}: no config for {}; make them with `troupe fleet-keys {} --hosts {} --operators bridge` (and `chown -R {UID} {}`: the image runs as user {UID})",
            dir.display(),
            missing.iter().map(|m| format!("{m}.json5")).collect::<Vec<_>>().join(", "),
            dir.display(),
            specs.join(","),
            dir.display()
        )
    }

    /// The fleet's services, laid out as `layout` says (a secured fleet
    /// keeps one router: its identities are the hosts' and the router's).
    pub(crate) fn services(&self, layout: Layout) -> anyhow::Result<Vec<Service>> {
        let hosts = self.hosts()?;
        let layout = if self.keys.is_some() {
            Layout::OneRouter
        } else {
            layout
        };
        let mut out = vec![Service {
            name: "router".into(),
            command: {
                let mut v = match &self.keys {
                    None => strings(&["router", "--listen", "tcp/0.0.0.0:7447", "--no-multicast"]),
                    Some(_) => strings(&[
                        "--zenoh-config",
                        "/keys/router.json5",
                        "router",
                        "--listen",
                        "tls/0.0.0.0:7447",
                    ]),
                };
                v.extend(["--lease".to_owned(), self.lease.to_string()]);
                v
            },
            ports: vec![("TROUPE_ROUTER_PORT".into(), 7447)],
            health: match &self.keys {
                None => strings(&["--connect", "tcp/127.0.0.1:7447", "--no-multicast", "ready"]),
                Some(_) => strings(&[
                    "--zenoh-config",
                    "/keys/bridge.json5",
                    "--connect",
                    "tls/localhost:7447",
                    "ready",
                ]),
            },
            depends: Vec::new(),
            comment: match layout {
                Layout::OneRouter => "The Zenoh router every container connects to (and `troupe list` on this machine, at 127.0.0.1:7447).".into(),
                Layout::RouterPerHost => "The fleet's Zenoh router: each host's router links to it (and `troupe list`, at its published port).".into(),
            },
            place: None,
            listens: Some(7447),
            identity: Some("router".into()),
        }];
        let path = match &self.source {
            Source::InImage(p) => p.clone(),
            Source::Mounted { file, .. } => format!("/stack/{file}"),
        };
        let split = self.plan.nodes.iter().any(|n| n.host.is_some());
        let mut robots = BTreeSet::new();
        for (host, devices) in &hosts {
            robots.extend(devices.iter().map(|d| d.robot));
            let router = match layout {
                Layout::OneRouter => "router".to_owned(),
                Layout::RouterPerHost => {
                    let name = host_router(host);
                    let mut command = strings(&["--connect", "tcp/router:7447", "--reconnect"]);
                    command.extend(strings(&[
                        "router",
                        "--listen",
                        "tcp/0.0.0.0:7447",
                        "--no-multicast",
                    ]));
                    command.extend(["--lease".to_owned(), self.lease.to_string()]);
                    out.push(Service {
                        name: name.clone(),
                        command,
                        ports: Vec::new(),
                        health: strings(&[
                            "--connect",
                            "tcp/127.0.0.1:7447",
                            "--no-multicast",
                            "ready",
                        ]),
                        depends: vec!["router".into()],
                        comment: format!(
                            "Host `{host}`'s router, on its machine, linked to the fleet's."
                        ),
                        place: Some(host.clone()),
                        listens: Some(7447),
                        identity: None,
                    });
                    name
                }
            };
            let mut command = self.net(host, &router);
            command.extend(["launch".to_owned(), path.clone()]);
            if split {
                command.extend(["--host".to_owned(), host.clone()]);
            }
            command.push("--no-bridge".into());
            let mut health = self.probe(host, &router);
            health.push("ready".into());
            health.extend(
                devices
                    .iter()
                    .map(|d| format!("{}:{}:{}", d.robot, d.interface, d.index)),
            );
            let nodes: Vec<&str> = self
                .plan
                .nodes
                .iter()
                .filter(|n| n.host.as_deref().unwrap_or("stack") == host)
                .map(|n| n.name.as_str())
                .collect();
            out.push(Service {
                name: host.clone(),
                command,
                ports: Vec::new(),
                health,
                depends: vec![router],
                comment: format!("Host `{host}`: {}, each its own process.", nodes.join(", ")),
                place: Some(host.clone()),
                listens: None,
                identity: Some(host.clone()),
            });
        }
        let robots: Vec<u16> = robots
            .into_iter()
            .filter_map(|r| u16::try_from(r).ok())
            .collect();
        if !robots.is_empty() {
            let mut command = self.net("bridge", "router");
            command.push("bridge".into());
            for r in &robots {
                command.extend(["-p".to_owned(), r.to_string()]);
            }
            command.extend(strings(&["--bind", "0.0.0.0"]));
            out.push(Service {
                name: "bridge".into(),
                command,
                ports: robots.iter().map(|r| (format!("TROUPE_PORT_{r}"), *r)).collect(),
                health: {
                    let mut v = self.probe("bridge", "router");
                    v.push("ready".into());
                    v
                },
                depends: hosts.iter().map(|(h, _)| h.clone()).collect(),
                comment: match layout {
                    Layout::OneRouter => "Player TCP for libplayerc, libplayerc++ and playerv: every robot port, on this machine's 127.0.0.1 only (Player has no authentication).".into(),
                    Layout::RouterPerHost => "Player TCP for libplayerc, libplayerc++ and playerv: every robot port (Player has no authentication: publish these on a trusted network only).".into(),
                },
                place: None,
                listens: None,
                identity: Some("bridge".into()),
            });
        }
        Ok(out)
    }

    /// The compose file.
    pub fn to_yaml(&self) -> anyhow::Result<String> {
        let services = self.services(Layout::OneRouter)?;
        let mut s = String::new();
        let _ = writeln!(
            s,
            "# Written by `{}`; regenerate rather than edit.",
            self.command
        );
        s.push_str(
            "#\n\
             #   cargo build --release && target/release/troupe image   # the image, troupe:latest\n\
             #   docker-compose up -d                                    # the fleet\n\
             #   troupe list                                             # its devices, from this machine\n\
             #   docker-compose down\n\
             #\n\
             # Every service runs the one troupe binary as PID 1 (it stops on SIGTERM).\n\
             # They meet at the router by service name on a private network: no\n\
             # multicast, no host networking. --reconnect: a container keeps trying\n\
             # the router, so start order does not matter and a restarted router or a\n\
             # healed network is rejoined without restarting anything; --lease: a\n\
             # container cut off for that many seconds has its devices withdrawn.\n\
             # Host ports: set TROUPE_ROUTER_PORT / TROUPE_PORT_<robot> (empty = any free port).\n\n",
        );
        s.push_str("version: \"2.4\"\n\nservices:\n");
        for svc in &services {
            svc.write_head(&mut s, &self.image);
            let mut volumes = Vec::new();
            if let Source::Mounted { host_dir, .. } = &self.source {
                if svc.name != "router" && svc.name != "bridge" {
                    volumes.push(format!("{host_dir}:/stack:ro"));
                }
            }
            if let Some(k) = &self.keys {
                volumes.push(format!("{k}:/keys:ro"));
            }
            if !volumes.is_empty() {
                s.push_str("    volumes:\n");
                for v in &volumes {
                    let _ = writeln!(s, "      - {}", yaml_str(v));
                }
            }
            if !svc.ports.is_empty() {
                s.push_str("    ports:\n");
                for (var, p) in &svc.ports {
                    let _ = writeln!(s, "      - \"127.0.0.1:${{{var}-{p}}}:{p}\"");
                }
            }
            s.push_str("    networks: [fleet]\n");
            s.push_str("    restart: unless-stopped\n");
            svc.write_health(&mut s);
            if !svc.depends.is_empty() {
                s.push_str("    depends_on:\n");
                for d in &svc.depends {
                    let _ = writeln!(s, "      {d}:\n        condition: service_healthy");
                }
            }
            s.push('\n');
        }
        s.push_str("networks:\n  fleet:\n");
        Ok(s)
    }
}

/// A host name that is also a valid compose service and DNS name.
fn check_service_name(h: &str) -> anyhow::Result<()> {
    let ok = !h.is_empty()
        && h.len() <= 63
        && h.bytes()
            .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'-')
        && !h.starts_with('-');
    if ok {
        Ok(())
    } else {
        anyhow::bail!(
            "host `{h}` cannot be a container's name: use lower-case letters, digits and `-`"
        )
    }
}

pub(crate) fn strings(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| (*s).to_owned()).collect()
}

pub(crate) fn yaml_str(s: &str) -> String {
    serde_json::Value::String(s.to_owned()).to_string()
}

/// A flow list of double-quoted strings (JSON's quoting is YAML's).
pub(crate) fn yaml_list(v: &[String]) -> String {
    let items: Vec<String> = v.iter().map(|x| yaml_str(x)).collect();
    format!("[{}]", items.join(", "))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ldd_output_gives_the_files_to_ship() {
        let text = "\tlinux-vdso.so.1 (0x00007ffd)\n\
                    \tlibgcc_s.so.1 => /lib/x86_64-linux-gnu/libgcc_s.so.1 (0x00007f1)\n\
                    \tlibc.so.6 => /lib/x86_64-linux-gnu/libc.so.6 (0x00007f2)\n\
                    \t/lib64/ld-linux-x86-64.so.2 (0x00007f3)\n";
        let libs = parse_ldd(text).unwrap();
        assert_eq!(
            libs,
            [
                "/lib/x86_64-linux-gnu/libgcc_s.so.1",
                "/lib/x86_64-linux-gnu/libc.so.6",
                "/lib64/ld-linux-x86-64.so.2"
            ]
            .map(PathBuf::from)
        );
        let e = parse_ldd("\tlibfoo.so.1 => not found\n").unwrap_err();
        assert!(e.to_string().contains("libfoo.so.1 is not found"), "{e}");
    }

    #[test]
    fn volume_paths_are_relative_to_the_compose_file() {
        assert_eq!(
            relative_to(Path::new("worlds"), Path::new("")).unwrap(),
            "./worlds"
        );
        assert_eq!(
            relative_to(Path::new("a/b"), Path::new("a/c")).unwrap(),
            "../b"
        );
        assert_eq!(relative_to(Path::new("a"), Path::new("a")).unwrap(), ".");
        assert_eq!(
            relative_to(Path::new("/srv/w"), Path::new("/tmp")).unwrap(),
            "/srv/w"
        );
    }

    #[test]
    fn host_names_must_be_service_names() {
        assert!(check_service_name("robot6665").is_ok());
        let e = check_service_name("Robot_1").unwrap_err();
        assert!(e.to_string().contains("lower-case"), "{e}");
    }
}
