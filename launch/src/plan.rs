//! Launch plans: what `troupe plan robot.cfg` prints and `troupe launch` runs.
//!
//! A plan is one entry per node process: its driver, its options in SI units,
//! the devices it provides and requires as concrete keys (with Player's keys
//! such as `odometry` kept as roles), its host, restart policy and start
//! order. It is written as TOML, meant to be read and edited by people.
//!
//! `from_cfg` translates a Player `.cfg`; `check` validates any plan (also
//! one loaded from TOML): every driver exists and accepts its options, no
//! device is provided twice, every requirement has exactly one provider or
//! is declared external, and the start order has no cycle.

use std::collections::{BTreeMap, HashMap};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use troupe_msgs::addr::AddrError;
use troupe_msgs::{keys, DevAddr, Device};
use troupe_node::{Section, Unit};

use crate::catalog::Catalog;
use crate::cfg::{self, CfgFile, Value};

/// What a node's supervisor does when it exits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Policy {
    /// Leave it down.
    Never,
    /// Restart it when it fails (non-zero exit or a signal).
    #[default]
    OnFailure,
    /// Restart it whenever it exits.
    Always,
}

/// Restart policy of a node.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Restart {
    /// When to restart.
    #[serde(default)]
    pub policy: Policy,
    /// Give up after this many restarts within `window` seconds.
    #[serde(default = "default_max")]
    pub max: u32,
    /// Seconds.
    #[serde(default = "default_window")]
    pub window: f64,
    /// Seconds before the first restart; doubles on each quick failure, up to 5 s.
    #[serde(default = "default_backoff")]
    pub backoff: f64,
}

fn default_max() -> u32 {
    5
}
fn default_window() -> f64 {
    60.0
}
fn default_backoff() -> f64 {
    0.1
}

impl Default for Restart {
    fn default() -> Self {
        Restart {
            policy: Policy::OnFailure,
            max: default_max(),
            window: default_window(),
            backoff: default_backoff(),
        }
    }
}

/// A device a node provides or requires.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DeviceRef {
    /// Its data key, `robot/6665/laser/0`.
    pub device: String,
    /// Player's key for it in this driver (`odometry`, `input`, `laser`…).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub role: Option<String>,
}

impl DeviceRef {
    fn parse(&self) -> Result<Device, AddrError> {
        keys::parse_data(&self.device)
    }
}

/// One node process.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NodeSpec {
    /// Unique name, used in logs and log files.
    pub name: String,
    /// Player driver name.
    pub driver: String,
    /// Host that runs it (`troupe launch --host NAME`); none = wherever the plan is launched.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub host: Option<String>,
    /// Nodes start in increasing order; a node starts once what it requires is live.
    #[serde(default)]
    pub start_order: u32,
    /// Restart policy.
    #[serde(default)]
    pub restart: Restart,
    /// Devices it provides.
    #[serde(default)]
    pub provides: Vec<DeviceRef>,
    /// Devices it requires.
    #[serde(default)]
    pub requires: Vec<DeviceRef>,
    /// Driver options by Player's names, lengths in metres and angles in radians.
    #[serde(default)]
    pub options: serde_json::Map<String, serde_json::Value>,
    /// Where it came from (`robot.cfg:12:1`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<String>,
    /// Where each option was written, for messages.
    #[serde(skip)]
    pub option_pos: BTreeMap<String, String>,
}

impl NodeSpec {
    /// The node's section, as `troupe node` takes it.
    ///
    /// # Errors
    ///
    /// A device that is no data key.
    pub fn section(&self) -> Result<Section, AddrError> {
        let addr = |r: &DeviceRef| -> Result<DevAddr, AddrError> {
            let d = r.parse()?;
            Ok(DevAddr {
                key: r.role.clone(),
                host: None,
                robot: Some(d.robot),
                interface: d.interface,
                index: d.index,
            })
        };
        let mut s = Section::new(&self.driver);
        s.provides = self.provides.iter().map(addr).collect::<Result<_, _>>()?;
        s.requires = self.requires.iter().map(addr).collect::<Result<_, _>>()?;
        s.options = self.options.clone();
        Ok(s)
    }
}

/// Plan-wide settings.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Meta {
    /// The file the plan was made from.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<String>,
    /// Devices provided outside this plan (another host, another launch).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub external: Vec<String>,
    /// ROS 2 on for every node (a cfg's `ros2 ( … )` section).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ros2: Option<troupe_node::Ros2Settings>,
}

/// A launch plan.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Plan {
    /// Plan-wide settings.
    #[serde(default)]
    pub launch: Meta,
    /// The nodes.
    #[serde(default, rename = "node")]
    pub nodes: Vec<NodeSpec>,
}

/// What translating or checking a plan found.
#[derive(Debug, Default)]
pub struct Report {
    /// Problems that stop the plan.
    pub errors: Vec<String>,
    /// Things worth saying (unused options, ignored plugins).
    pub warnings: Vec<String>,
}

/// Why a plan cannot run: every problem found, one per line.
#[derive(Debug, thiserror::Error)]
#[error("{}", .0.join("\n"))]
pub struct PlanError(pub Vec<String>);

/// Fields every driver section may have that are not driver options.
const GENERIC: &[&str] = &["name", "provides", "requires", "plugin", "alwayson"];

fn num(text: &str) -> serde_json::Value {
    if let Ok(i) = text.parse::<i64>() {
        return i.into();
    }
    // INVARIANT: the parser only keeps numbers that parse as f64.
    serde_json::Number::from_f64(text.parse::<f64>().unwrap_or(0.0))
        .map_or(serde_json::Value::Null, serde_json::Value::Number)
}

/// A cfg's `ros2 ( domain 0 distro "jazzy" namespace "/robot_{robot}"
/// cmd_vel_timeout 0.5 )`: ROS 2 on for the launch, with these settings.
fn ros2_section(s: &cfg::Section) -> Result<troupe_node::Ros2Settings, String> {
    let mut r = troupe_node::Ros2Settings::default();
    for f in &s.fields {
        let text = match &f.value {
            Value::Num(t) | Value::Str(t) | Value::Word(t) => t.clone(),
            _ => return Err(format!("{}: `{}` takes one value", f.pos, f.name)),
        };
        let number = |what: &str| format!("{}: `{}` must be {what}, not `{text}`", f.pos, f.name);
        match f.name.as_str() {
            "domain" => r.domain = Some(text.parse().map_err(|_| number("a ROS domain (0-232)"))?),
            "distro" => r.distro = Some(text),
            "namespace" => r.namespace = Some(text),
            "cmd_vel_timeout" => {
                r.cmd_vel_timeout = Some(text.parse().map_err(|_| number("seconds"))?)
            }
            other => {
                return Err(format!(
                    "{}: `{other}` is no ros2 setting (domain, distro, namespace, cmd_vel_timeout)",
                    f.pos
                ))
            }
        }
    }
    if let Some(c) = s.children.first() {
        return Err(format!(
            "{}: section `{}` inside the ros2 section",
            c.pos, c.kind
        ));
    }
    Ok(r)
}

/// The directory that relative file names in `file` are read against,
/// absolute so that the plan runs from any directory.
fn cfg_dir(file: &Path) -> PathBuf {
    let dir = match file.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_owned(),
        _ => Path::new(".").to_owned(),
    };
    std::fs::canonicalize(&dir).unwrap_or(dir)
}

/// A cfg value as JSON, scaled to SI where the driver reads a length or
/// angle; file names are made absolute against `dir`.
fn to_json(
    v: &Value,
    unit: Option<Unit>,
    units: &cfg::Units,
    dir: &Path,
) -> Result<serde_json::Value, String> {
    let scale = |text: &str, factor: f64| -> Result<serde_json::Value, String> {
        let x: f64 = text
            .parse()
            .map_err(|_| format!("`{text}` is not a number"))?;
        serde_json::Number::from_f64(x * factor)
            .map(serde_json::Value::Number)
            .ok_or_else(|| format!("`{text}` is not finite"))
    };
    Ok(match (v, unit) {
        (Value::Num(n), Some(Unit::Length)) => scale(n, units.length)?,
        (Value::Num(n), Some(Unit::Angle)) => scale(n, units.angle)?,
        (Value::Num(n), _) => num(n),
        (Value::Str(s) | Value::Word(s), Some(Unit::Path)) => {
            dir.join(s).display().to_string().into()
        }
        (Value::Str(s) | Value::Word(s), _) => s.clone().into(),
        (Value::Bool(b), _) => (*b).into(),
        (Value::Tuple(items), u) => {
            let each = |i: usize| match u {
                Some(Unit::Tuple(us)) => us.get(i).copied(),
                Some(Unit::Lengths) => Some(Unit::Length),
                Some(Unit::Angles) => Some(Unit::Angle),
                _ => None,
            };
            serde_json::Value::Array(
                items
                    .iter()
                    .enumerate()
                    .map(|(i, x)| to_json(x, each(i), units, dir))
                    .collect::<Result<_, _>>()?,
            )
        }
    })
}

/// Folds one `stage` section into the single simulator node, as Player's
/// plugin shares one world between all its sections: the first `worldfile`
/// wins (made relative to the cfg's directory), each `model` becomes an
/// entry of the node's `models` option with the section's devices.
///
/// The one simulator runs on one host: the host the sections name (an
/// address's host field), which must be the same wherever one is named.
#[allow(clippy::too_many_arguments)]
fn merge_stage(
    stage: &mut Option<NodeSpec>,
    options: &mut serde_json::Map<String, serde_json::Value>,
    provides: Vec<DeviceRef>,
    host: Option<String>,
    source: &Path,
    at: String,
    option_pos: BTreeMap<String, String>,
    report: &mut Report,
) {
    if let (Some(h), Some(node)) = (&host, stage.as_ref()) {
        if let Some(other) = node.host.as_ref().filter(|o| *o != h) {
            report.errors.push(format!(
                "{at}: this stage section runs on host `{h}`, an earlier one on `{other}`: \
                 all stage sections are one simulator, on one host"
            ));
        }
    }
    let at_section = at.clone();
    let node = stage.get_or_insert_with(|| NodeSpec {
        name: "stage".into(),
        driver: "stage".into(),
        host: None,
        start_order: 0,
        restart: Restart::default(),
        provides: Vec::new(),
        requires: Vec::new(),
        options: serde_json::Map::new(),
        source: Some(at),
        option_pos: BTreeMap::new(),
    });
    if let Some(serde_json::Value::String(w)) = options.remove("worldfile") {
        if !node.options.contains_key("worldfile") {
            node.options.insert(
                "worldfile".into(),
                cfg_dir(source).join(w).display().to_string().into(),
            );
        }
    }
    if let Some(model) = options.remove("model") {
        let devices: Vec<serde_json::Value> = provides
            .iter()
            .filter_map(|r| keys::parse_data(&r.device).ok())
            .map(|d| d.to_string().into())
            .collect();
        let entry = serde_json::json!({ "model": model, "provides": devices });
        match node
            .options
            .entry("models")
            .or_insert_with(|| serde_json::Value::Array(Vec::new()))
        {
            serde_json::Value::Array(a) => a.push(entry),
            other => *other = serde_json::Value::Array(vec![entry]),
        }
    }
    // One simulator: an option given again keeps its first value, and a
    // different one is said; every place an option is given is kept, so a
    // warning about it names them all.
    for (k, v) in std::mem::take(options) {
        match node.options.get(&k) {
            Some(first) if *first != v => {
                let here = option_pos.get(&k).unwrap_or(&at_section);
                let there = node.option_pos.get(&k).cloned().unwrap_or_default();
                report.warnings.push(format!(
                    "{here}: option `{k}` {v} differs from {first} at {there}: all stage \
                     sections are one simulator, and the first value stands"
                ));
            }
            Some(_) => {}
            None => {
                node.options.insert(k, v);
            }
        }
    }
    for (k, pos) in option_pos {
        node.option_pos
            .entry(k)
            .and_modify(|p| {
                p.push_str(", ");
                p.push_str(&pos);
            })
            .or_insert(pos);
    }
    node.provides.extend(provides);
    if node.host.is_none() {
        node.host = host;
    }
}

/// Translates a parsed cfg into a plan; `robot` is the default robot field
/// (`-p PORT`). Problems are collected in the report, not returned early.
pub fn from_cfg(
    file: &CfgFile,
    source: &Path,
    robot: u32,
    catalog: &Catalog,
    report: &mut Report,
) -> Plan {
    let mut plan = Plan {
        launch: Meta {
            source: Some(source.display().to_string()),
            external: Vec::new(),
            ros2: None,
        },
        nodes: Vec::new(),
    };
    for (p, pos) in &file.plugins {
        report.warnings.push(format!(
            "{pos}: plugin \"{p}\" ignored: Troupe's drivers are built in"
        ));
    }
    for g in &file.globals {
        report.warnings.push(format!(
            "{}: top-level field `{}` is not used",
            g.pos, g.name
        ));
    }
    let mut count: HashMap<String, u32> = HashMap::new();
    let mut unknown: BTreeMap<String, Vec<cfg::Pos>> = BTreeMap::new();
    let mut stage: Option<NodeSpec> = None;
    for s in &file.sections {
        if s.kind == "ros2" {
            match ros2_section(s) {
                Ok(r) => plan.launch.ros2 = Some(r),
                Err(e) => report.errors.push(e),
            }
            continue;
        }
        if s.kind != "driver" {
            report.errors.push(format!(
                "{}: unknown section type `{}`: a Player .cfg holds `driver ( … )` sections",
                s.pos, s.kind
            ));
            continue;
        }
        if let Some(c) = s.children.first() {
            report.errors.push(format!(
                "{}: section `{}` inside a driver section",
                c.pos, c.kind
            ));
            continue;
        }
        let Some(name_field) = s.field("name") else {
            report.errors.push(format!(
                "{}: driver section has no `name` (e.g. name \"sicklms200\")",
                s.pos
            ));
            continue;
        };
        let Value::Str(driver) = &name_field.value else {
            report.errors.push(format!(
                "{}: `name` must be a quoted driver name",
                name_field.pos
            ));
            continue;
        };
        // Each address of a field as the plan names it, and as the cfg wrote it.
        let mut refs = |field: &str| -> Option<Vec<(DeviceRef, DevAddr)>> {
            let Some(f) = s.field(field) else {
                return Some(Vec::new());
            };
            let Some(list) = f.value.strings() else {
                report.errors.push(format!(
                    "{}: `{field}` must be a list of quoted addresses like [\"laser:0\"]",
                    f.pos
                ));
                return None;
            };
            let mut out = Vec::new();
            for text in list {
                let text = text.trim();
                let parsed = text.parse::<DevAddr>().or_else(|e| {
                    // Only an unknown interface may be a Player 2 name.
                    if !matches!(e, AddrError::UnknownInterface { .. }) {
                        return Err(e);
                    }
                    let fixed = troupe_msgs::addr::player3_spelling(text).ok_or(e)?;
                    report.warnings.push(format!(
                        "{}: {field}: `{text}` uses a Player 2 interface name; read as `{fixed}`",
                        f.pos
                    ));
                    fixed.parse::<DevAddr>()
                });
                match parsed {
                    Ok(a) => out.push((
                        DeviceRef {
                            device: keys::data(&a.device(robot)),
                            role: a.key.clone(),
                        },
                        a,
                    )),
                    Err(e) => {
                        report.errors.push(format!("{}: {field}: {e}", f.pos));
                        return None;
                    }
                }
            }
            Some(out)
        };
        let (Some(provides), Some(requires)) = (refs("provides"), refs("requires")) else {
            continue;
        };
        // The host that runs the node: the last one its provides name.
        let host = provides.iter().rev().find_map(|(_, a)| a.host.clone());
        let provides: Vec<DeviceRef> = provides.into_iter().map(|(r, _)| r).collect();
        let Some(entry) = catalog.find(driver) else {
            unknown
                .entry(driver.clone())
                .or_default()
                .push(name_field.pos.clone());
            continue;
        };
        let mut options = serde_json::Map::new();
        let mut option_pos = BTreeMap::new();
        let mut bad = false;
        for f in &s.fields {
            if GENERIC.contains(&f.name.as_str()) {
                continue;
            }
            let unit = entry
                .units
                .iter()
                .find(|(n, _)| *n == f.name)
                .map(|(_, u)| *u);
            match to_json(&f.value, unit, &f.units, &cfg_dir(&f.pos.file)) {
                Ok(v) => {
                    options.insert(f.name.clone(), v);
                    option_pos.insert(f.name.clone(), f.pos.to_string());
                }
                Err(e) => {
                    report
                        .errors
                        .push(format!("{}: option `{}`: {e}", f.pos, f.name));
                    bad = true;
                }
            }
        }
        if bad {
            continue;
        }
        if driver == "stage" {
            merge_stage(
                &mut stage,
                &mut options,
                provides,
                host,
                source,
                s.pos.to_string(),
                option_pos,
                report,
            );
            continue;
        }
        // Player's passthrough: a `requires` address with a host is a device
        // of that Player server, for the driver to reach, not one to wire;
        // with Troupe's `namespace`, every address is a device of that
        // namespace, for the driver to relay.
        let passthrough = driver == "passthrough";
        let elsewhere = passthrough && options.contains_key("namespace");
        let (mut remote, mut there, mut wired) = (Vec::new(), Vec::new(), Vec::new());
        for (r, a) in requires {
            let dev = format!(
                "{}:{}:{}",
                a.robot.unwrap_or(robot),
                a.interface.name(),
                a.index
            );
            match a.host {
                Some(host) if passthrough => remote.push(format!("{host}:{dev}").into()),
                None if elsewhere => there.push(dev.into()),
                _ => wired.push(r),
            }
        }
        for (key, list) in [("remote", remote), ("elsewhere", there)] {
            if !list.is_empty() {
                options.insert(key.into(), serde_json::Value::Array(list));
            }
        }
        let requires: Vec<DeviceRef> = wired;
        let n = count.entry(driver.clone()).or_insert(0);
        *n += 1;
        plan.nodes.push(NodeSpec {
            name: if *n == 1 {
                driver.clone()
            } else {
                format!("{driver}-{n}")
            },
            driver: driver.clone(),
            host,
            start_order: 0,
            restart: Restart::default(),
            provides,
            requires,
            options,
            source: Some(s.pos.to_string()),
            option_pos,
        });
    }
    if let Some(mut st) = stage {
        // Player stepped its Stage plugin once per server update (100 Hz):
        // a world with `speedup 0` ran ~10x real time, not flat out.
        st.options
            .entry("update_rate")
            .or_insert(serde_json::Value::from(100));
        // Its plugin stopped the clock at quit_time and Player served on.
        st.options
            .entry("at_quit_time")
            .or_insert(serde_json::Value::from("pause"));
        plan.nodes.insert(0, st);
    }
    for (driver, places) in unknown {
        let also = match places.len() {
            1 => String::new(),
            n => format!(
                " ({n} sections: lines {})",
                places
                    .iter()
                    .map(|p| p.line.to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        };
        report.errors.push(format!(
            "{}: {}",
            places[0],
            catalog.unavailable(&driver, &also)
        ));
    }
    plan
}

/// Checks a plan and fills in start orders. Problems go to the report.
pub fn check(plan: &mut Plan, catalog: &Catalog, report: &mut Report) {
    let mut names = HashMap::new();
    for n in &plan.nodes {
        if names.insert(n.name.clone(), ()).is_some() {
            report
                .errors
                .push(format!("two nodes are called `{}`", n.name));
        }
    }
    // Drivers and options.
    for n in &plan.nodes {
        let at = n
            .source
            .clone()
            .unwrap_or_else(|| format!("node `{}`", n.name));
        let Some(entry) = catalog.find(&n.driver) else {
            report
                .errors
                .push(format!("{at}: {}", catalog.unavailable(&n.driver, "")));
            continue;
        };
        match n.section() {
            Err(e) => report.errors.push(format!("{at}: {e}")),
            Ok(section) => match (entry.check)(&section) {
                Ok(unused) => {
                    for o in unused.options {
                        let place = n.option_pos.get(&o).unwrap_or(&at);
                        report.warnings.push(format!(
                            "{place}: option `{o}` is not used by driver `{}`",
                            n.driver
                        ));
                    }
                    for r in unused.requires {
                        report.warnings.push(format!(
                            "{at}: `{r}` in requires is not used by driver `{}`",
                            n.driver
                        ));
                    }
                }
                Err(e) => report.errors.push(format!("{at}: {e}")),
            },
        }
    }
    // Providers.
    let mut provider: BTreeMap<Device, usize> = BTreeMap::new();
    for (i, n) in plan.nodes.iter().enumerate() {
        for r in &n.provides {
            let Ok(d) = r.parse() else { continue };
            if let Some(&j) = provider.get(&d) {
                let other = &plan.nodes[j];
                report.errors.push(format!(
                    "{d} is provided twice: by `{}` ({}) and by `{}` ({})",
                    other.name,
                    other.source.as_deref().unwrap_or("plan"),
                    n.name,
                    n.source.as_deref().unwrap_or("plan")
                ));
            } else {
                provider.insert(d, i);
            }
        }
    }
    let external: Vec<Device> = plan
        .launch
        .external
        .iter()
        .filter_map(|k| match keys::parse_data(k) {
            Ok(d) => Some(d),
            Err(e) => {
                report.errors.push(format!("[launch] external: {e}"));
                None
            }
        })
        .collect();
    // Requirements.
    let mut deps: Vec<Vec<usize>> = vec![Vec::new(); plan.nodes.len()];
    for (i, n) in plan.nodes.iter().enumerate() {
        for r in &n.requires {
            let Ok(d) = r.parse() else { continue };
            match provider.get(&d) {
                Some(&j) if j == i => report.errors.push(format!(
                    "node `{}` requires {d}, which it provides itself",
                    n.name
                )),
                Some(&j) => deps[i].push(j),
                None if external.contains(&d) => {}
                None => {
                    let similar: Vec<String> = provider
                        .keys()
                        .filter(|p| {
                            p.interface == d.interface || (p.robot == d.robot && p.index == d.index)
                        })
                        .map(ToString::to_string)
                        .collect();
                    let hint = if similar.is_empty() {
                        "no similar device is provided".to_owned()
                    } else {
                        format!("similar devices provided: {}", similar.join(", "))
                    };
                    report.errors.push(format!(
                        "{}: node `{}` requires {d}, which nothing provides ({hint}); add a driver that provides it, or declare it in [launch] external if it runs elsewhere",
                        n.source.as_deref().unwrap_or("plan"),
                        n.name
                    ));
                }
            }
        }
    }
    // Start order: longest chain of requirements below each node.
    let mut order = vec![0u32; plan.nodes.len()];
    let mut state = vec![0u8; plan.nodes.len()]; // 0 new, 1 visiting, 2 done
    fn visit(
        i: usize,
        deps: &[Vec<usize>],
        order: &mut [u32],
        state: &mut [u8],
        path: &mut Vec<usize>,
    ) -> Result<u32, Vec<usize>> {
        match state[i] {
            2 => return Ok(order[i]),
            1 => {
                let at = path.iter().position(|&p| p == i).unwrap_or(0);
                return Err(path[at..].to_vec());
            }
            _ => {}
        }
        state[i] = 1;
        path.push(i);
        let mut o = 1;
        for &j in &deps[i] {
            o = o.max(visit(j, deps, order, state, path)? + 1);
        }
        path.pop();
        state[i] = 2;
        order[i] = o;
        Ok(o)
    }
    for i in 0..plan.nodes.len() {
        if let Err(cycle) = visit(i, &deps, &mut order, &mut state, &mut Vec::new()) {
            let names: Vec<&str> = cycle.iter().map(|&c| plan.nodes[c].name.as_str()).collect();
            report.errors.push(format!(
                "requirements form a cycle: {} → {}",
                names.join(" → "),
                names[0]
            ));
            return;
        }
    }
    for (n, o) in plan.nodes.iter_mut().zip(order) {
        n.start_order = o;
    }
}

/// Reads a plan from a `.cfg` or a `.toml` file and checks it.
///
/// # Errors
///
/// Every problem found, each with its place.
pub fn load(path: &Path, robot: u32, catalog: &Catalog) -> Result<(Plan, Vec<String>), PlanError> {
    load_with(path, robot, &[], catalog)
}

/// [`load`], with `external` devices (`laser:0`, `6665:laser:0`) added to
/// the plan's `[launch] external`: provided by something outside the plan
/// (another host, `troupe play`).
///
/// # Errors
///
/// As [`load`], and a device that does not parse.
pub fn load_with(
    path: &Path,
    robot: u32,
    external: &[String],
    catalog: &Catalog,
) -> Result<(Plan, Vec<String>), PlanError> {
    let mut report = Report::default();
    let is_toml = path.extension().is_some_and(|e| e == "toml");
    let plan = if is_toml {
        let text = std::fs::read_to_string(path)
            .map_err(|e| PlanError(vec![format!("{}: {e}", path.display())]))?;
        toml::from_str::<Plan>(&text)
            .map_err(|e| PlanError(vec![format!("{}: {e}", path.display())]))?
    } else {
        let file = cfg::parse_file(path).map_err(|e| PlanError(vec![e.to_string()]))?;
        from_cfg(&file, path, robot, catalog, &mut report)
    };
    let mut plan = plan;
    for e in external {
        match e.parse::<troupe_msgs::DevAddr>() {
            Ok(a) => plan.launch.external.push(keys::data(&a.device(robot))),
            Err(err) => report.errors.push(format!("--external {e}: {err}")),
        }
    }
    checked(plan, catalog, report)
}

/// Checks `plan` unless building it already failed: the plan and its
/// warnings, or every error.
fn checked(
    mut plan: Plan,
    catalog: &Catalog,
    mut report: Report,
) -> Result<(Plan, Vec<String>), PlanError> {
    if report.errors.is_empty() {
        check(&mut plan, catalog, &mut report);
    }
    if report.errors.is_empty() {
        Ok((plan, report.warnings))
    } else {
        Err(PlanError(report.errors))
    }
}

fn toml_value(v: &serde_json::Value) -> String {
    match toml::Value::try_from(v) {
        Ok(t) => t.to_string(),
        Err(_) => v.to_string(),
    }
}

fn toml_str(s: &str) -> String {
    toml::Value::String(s.to_owned()).to_string()
}

fn refs_toml(v: &[DeviceRef]) -> String {
    let items: Vec<String> = v
        .iter()
        .map(|r| match &r.role {
            Some(role) => format!(
                "{{ device = {}, role = {} }}",
                toml_str(&r.device),
                toml_str(role)
            ),
            None => format!("{{ device = {} }}", toml_str(&r.device)),
        })
        .collect();
    format!("[{}]", items.join(", "))
}

/// The plan as a commented, human-editable TOML launch file.
pub fn to_toml(plan: &Plan) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# Troupe launch plan. Run it with `troupe launch <this file>`; edit freely."
    );
    let _ = writeln!(
        s,
        "# Options are in SI units (metres, radians); one [[node]] per process."
    );
    let _ = writeln!(s, "\n[launch]");
    if let Some(src) = &plan.launch.source {
        let _ = writeln!(s, "source = {}", toml_str(src));
    }
    let ext: Vec<String> = plan.launch.external.iter().map(|e| toml_str(e)).collect();
    let _ = writeln!(
        s,
        "# Devices provided elsewhere (another host or launch), e.g. \"robot/6665/laser/0\"."
    );
    let _ = writeln!(s, "external = [{}]", ext.join(", "));
    if let Some(r) = &plan.launch.ros2 {
        let _ = writeln!(
            s,
            "\n# Every node also shows its devices to ROS 2 (docs/ros2.md)."
        );
        match toml::to_string(r) {
            Ok(t) => {
                let _ = write!(s, "[launch.ros2]\n{t}");
            }
            Err(e) => tracing::error!("writing the plan's ros2 settings: {e}"),
        }
    }
    for n in &plan.nodes {
        let _ = writeln!(s, "\n[[node]]");
        let _ = writeln!(s, "name = {}", toml_str(&n.name));
        let _ = writeln!(s, "driver = {}", toml_str(&n.driver));
        if let Some(h) = &n.host {
            let _ = writeln!(s, "host = {}", toml_str(h));
        }
        let _ = writeln!(s, "start_order = {}", n.start_order);
        let p = match n.restart.policy {
            Policy::Never => "never",
            Policy::OnFailure => "on-failure",
            Policy::Always => "always",
        };
        let _ = writeln!(
            s,
            "restart = {{ policy = \"{p}\", max = {}, window = {:?}, backoff = {:?} }}",
            n.restart.max, n.restart.window, n.restart.backoff
        );
        let _ = writeln!(s, "provides = {}", refs_toml(&n.provides));
        let _ = writeln!(s, "requires = {}", refs_toml(&n.requires));
        if let Some(src) = &n.source {
            let _ = writeln!(s, "source = {}", toml_str(src));
        }
        let _ = writeln!(s, "[node.options]");
        for (k, v) in &n.options {
            let key = if k
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
            {
                k.clone()
            } else {
                toml_str(k)
            };
            let _ = writeln!(s, "{key} = {}", toml_value(v));
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan_of(text: &str) -> Result<(Plan, Vec<String>), PlanError> {
        let file =
            cfg::parse_str(text, Path::new("t.cfg")).map_err(|e| PlanError(vec![e.to_string()]))?;
        let mut report = Report::default();
        let catalog = crate::catalog::tests::catalog();
        let plan = from_cfg(&file, Path::new("t.cfg"), 6665, &catalog, &mut report);
        checked(plan, &catalog, report)
    }

    const STACK: &str = "driver( name \"dummy\" provides [\"ranger:0\"] rate 20 colour \"red\" )\n\
                         driver( name \"rangertolaser\" requires [\"ranger:0\"] provides [\"laser:0\"] )\n";

    #[test]
    fn a_ros2_section_turns_ros2_on_and_round_trips_through_toml() {
        let (plan, _) = plan_of(
            "ros2 ( domain 3 distro \"humble\" namespace \"/fleet/r{robot}\" cmd_vel_timeout 0.25 )\n\
             driver( name \"dummy\" provides [\"ranger:0\"] )\n",
        )
        .unwrap();
        let want = troupe_node::Ros2Settings {
            domain: Some(3),
            distro: Some("humble".into()),
            namespace: Some("/fleet/r{robot}".into()),
            cmd_vel_timeout: Some(0.25),
        };
        assert_eq!(plan.launch.ros2.as_ref(), Some(&want));
        let back: Plan = toml::from_str(&to_toml(&plan)).unwrap();
        assert_eq!(back.launch.ros2, Some(want));
        let e = plan_of("ros2 ( domian 3 )\n").unwrap_err().to_string();
        assert!(e.contains("1:8: `domian` is no ros2 setting"), "{e}");
        let e = plan_of("ros2 ( domain \"x\" )\n").unwrap_err().to_string();
        assert!(e.contains("`domain` must be a ROS domain"), "{e}");
    }

    #[test]
    fn requires_a_driver_does_not_use_are_warned_about() {
        let (_, warnings) = plan_of(
            "driver( name \"dummy\" provides [\"ranger:0\" \"laser:1\"] )\n\
             driver( name \"rangertolaser\" requires [\"ranger:0\" \"laser:1\"] provides [\"laser:0\"] )\n",
        )
        .unwrap();
        assert_eq!(
            warnings,
            vec![
                "t.cfg:2:1: `6665:laser:1` in requires is not used by driver `rangertolaser`"
                    .to_owned()
            ]
        );
    }

    #[test]
    fn options_of_merged_stage_sections_are_warned_about_wherever_given() {
        let (plan, warnings) = plan_of(
            "driver( name \"stage\" provides [\"simulation:0\"] worldfile \"../worlds/simple.world\" bogus 1 )\n\
             driver( name \"stage\" provides [\"position2d:0\"] model \"r0\" bogus 2 )\n",
        )
        .unwrap();
        assert_eq!(plan.nodes.len(), 1);
        assert_eq!(plan.nodes[0].options["bogus"], 1);
        assert_eq!(
            warnings,
            vec![
                "t.cfg:2:59: option `bogus` 2 differs from 1 at t.cfg:1:83: all stage sections \
                 are one simulator, and the first value stands"
                    .to_owned(),
                "t.cfg:1:83, t.cfg:2:59: option `bogus` is not used by driver `stage`".to_owned(),
            ]
        );
    }

    #[test]
    fn a_stack_becomes_ordered_nodes_and_round_trips_through_toml() {
        let (plan, warnings) = plan_of(STACK).unwrap();
        assert_eq!(plan.nodes.len(), 2);
        assert_eq!(plan.nodes[0].start_order, 1);
        assert_eq!(plan.nodes[1].start_order, 2);
        assert_eq!(plan.nodes[1].requires[0].device, "robot/6665/ranger/0");
        assert_eq!(plan.nodes[0].options["rate"], 20);
        assert_eq!(
            warnings,
            vec!["t.cfg:1:52: option `colour` is not used by driver `dummy`".to_owned()]
        );
        let text = to_toml(&plan);
        let back: Plan = toml::from_str(&text).unwrap();
        let mut plan = plan;
        plan.nodes.iter_mut().for_each(|n| n.option_pos.clear());
        assert_eq!(back, plan, "{text}");
    }

    #[test]
    fn robot_port_and_roles_are_kept() {
        let file = cfg::parse_str(
            "driver( name \"rangertolaser\" requires [\"input::ranger:0\"] provides [\"laser:0\"] )\ndriver( name \"dummy\" provides [\"ranger:0\"] )",
            Path::new("t.cfg"),
        )
        .unwrap();
        let mut r = Report::default();
        let catalog = crate::catalog::tests::catalog();
        let mut plan = from_cfg(&file, Path::new("t.cfg"), 7000, &catalog, &mut r);
        check(&mut plan, &catalog, &mut r);
        assert!(r.errors.is_empty(), "{:?}", r.errors);
        assert_eq!(plan.nodes[0].requires[0].device, "robot/7000/ranger/0");
        assert_eq!(plan.nodes[0].requires[0].role.as_deref(), Some("input"));
        assert_eq!(plan.nodes[0].start_order, 2);
        let sec = plan.nodes[0].section().unwrap();
        assert_eq!(sec.requires[0].to_string(), "input::7000:ranger:0");
    }

    #[test]
    fn problems_are_all_reported_with_places() {
        let e = plan_of(
            "driver( name \"foo\" provides [\"laser:0\"] )\n\
             driver( name \"rangertolaser\" requires [\"ranger:3\"] provides [\"laser:1\"] )\n\
             driver( name \"dummy\" provides [\"ranger:0\"] )\n",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("t.cfg:1:9: driver `foo` is not available in Troupe; available: dummy, rangertolaser"), "{e}");
        // A Player driver Troupe lacks says what it is and what to use.
        let e = plan_of("driver( name \"p2os_position\" provides [\"position2d:0\"] )\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("driver `p2os_position` is not available in Troupe (Player's: Player 1's name for a Pioneer's base); use `p2os`"),
            "{e}"
        );
        let e = plan_of(
            "driver( name \"rangertolaser\" requires [\"ranger:3\"] provides [\"laser:1\"] )\n\
             driver( name \"dummy\" provides [\"ranger:0\"] )\n",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("requires 6665:ranger:3, which nothing provides (similar devices provided: 6665:ranger:0)"), "{e}");
        let e = plan_of("driver( name \"dummy\" provides [\"laser:0\"] )\ndriver( name \"dummy\" provides [\"laser:0\"] )")
            .unwrap_err()
            .to_string();
        assert!(e.contains("6665:laser:0 is provided twice: by `dummy` (t.cfg:1:1) and by `dummy-2` (t.cfg:2:1)"), "{e}");
        let e = plan_of("driver( name \"dummy\" provides [\"laser:0\"] rate \"fast\" )")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(
                "t.cfg:1:1: configuration of driver `dummy`: option invalid type: string \"fast\""
            ),
            "{e}"
        );
        let e = plan_of("robot( name \"x\" )").unwrap_err().to_string();
        assert!(e.contains("unknown section type `robot`"), "{e}");
        let e = plan_of("driver( name \"dummy\" provides [\"lazer:0\"] )")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("t.cfg:1:22: provides: unknown interface `lazer`"),
            "{e}"
        );
    }

    #[test]
    fn external_devices_satisfy_requirements() {
        let mut plan = plan_of("driver( name \"dummy\" provides [\"laser:0\"] )")
            .unwrap()
            .0;
        plan.nodes.push(NodeSpec {
            name: "conv".into(),
            driver: "rangertolaser".into(),
            host: Some("b".into()),
            start_order: 0,
            restart: Restart::default(),
            provides: vec![DeviceRef {
                device: "robot/6665/laser/1".into(),
                role: None,
            }],
            requires: vec![DeviceRef {
                device: "robot/6665/ranger/9".into(),
                role: None,
            }],
            options: Default::default(),
            source: None,
            option_pos: Default::default(),
        });
        let mut r = Report::default();
        check(&mut plan, &crate::catalog::tests::catalog(), &mut r);
        assert_eq!(r.errors.len(), 1);
        plan.launch.external.push("robot/6665/ranger/9".into());
        let mut r = Report::default();
        check(&mut plan, &crate::catalog::tests::catalog(), &mut r);
        assert!(r.errors.is_empty(), "{:?}", r.errors);
    }

    #[test]
    fn units_scale_lengths_and_angles() {
        let u = cfg::Units {
            length: 0.01,
            angle: std::f64::consts::PI / 180.0,
        };
        let pose = Value::Tuple(vec![
            Value::Num("10".into()),
            Value::Num("0".into()),
            Value::Num("90".into()),
        ]);
        let j = to_json(
            &pose,
            Some(Unit::Tuple(&[Unit::Length, Unit::Length, Unit::Angle])),
            &u,
            Path::new("/cfg"),
        )
        .unwrap();
        assert_eq!(j[0], 0.1);
        assert!((j[2].as_f64().unwrap() - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        let here = Path::new("/cfg");
        assert_eq!(to_json(&Value::Num("3".into()), None, &u, here).unwrap(), 3);
        let file = Value::Str("maps/cave.png".into());
        assert_eq!(
            to_json(&file, Some(Unit::Path), &u, here).unwrap(),
            "/cfg/maps/cave.png"
        );
        assert_eq!(
            to_json(&Value::Str("/abs.png".into()), Some(Unit::Path), &u, here).unwrap(),
            "/abs.png"
        );
    }
}
