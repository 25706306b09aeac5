//! `troupe cmd` and `troupe call`: act on a device from the shell, as
//! `ros2 topic pub` and `ros2 service call` do.
//!
//! A command or request is named as its key names it (`vel`, `goal`,
//! `get_pose2d`); its message is read from the values that follow, in the
//! order of the message's fields (`vel 0.3 0 0.2`: x, y, yaw), the fields
//! left out keeping their defaults, or whole from `--json`. Both go through
//! the session's identity, so a fleet's access rules hold here as anywhere.

use std::io::Write;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Args;
use serde_json::Value;
use troupe_client::{Client, ClientError};
use troupe_msgs::{decode_any, default_of, encode_from, routed, DevAddr, Device, Route};
use troupe_node::{Mode, ZenohArgs};

/// What `cmd` and `call` send, and where.
#[derive(Debug, Args)]
pub struct Message {
    /// The device (`position2d:0`, `6666:planner:0`).
    pub device: String,
    /// The command or request, as its key names it (`vel`, `goal`,
    /// `get_pose2d`…); a wrong name lists what the device takes.
    pub name: String,
    /// The message's fields in order (`vel 0.3 0 0.2`: forward, sideways,
    /// turn; `get_pose2d r0`); fields left out keep their defaults.
    #[arg(allow_negative_numbers = true)]
    pub values: Vec<String>,
    /// The whole message as JSON instead of VALUES.
    #[arg(long, value_name = "JSON", conflicts_with = "values")]
    pub json: Option<String>,
    /// Robot (port) for a device that names none.
    #[arg(short = 'p', long = "robot", value_name = "PORT", default_value_t = troupe_msgs::DEFAULT_ROBOT)]
    pub robot: u32,
}

/// Flags of `troupe cmd`.
#[derive(Debug, Args)]
pub struct CmdArgs {
    #[command(flatten)]
    pub message: Message,
    /// Keep sending it for this many seconds. A motion command (`vel`,
    /// `car`) is repeated until Ctrl-C without it; the base is stopped at the end.
    #[arg(long = "for", value_name = "SECS", value_parser = troupe_node::args::seconds)]
    pub seconds: Option<f64>,
    /// How often to send it while it is held, per second.
    #[arg(long, value_name = "HZ", default_value_t = 10.0, value_parser = troupe_node::args::finite)]
    pub rate: f64,
}

/// Flags of `troupe call`.
#[derive(Debug, Args)]
pub struct CallArgs {
    #[command(flatten)]
    pub message: Message,
    /// Seconds to wait for the answer.
    #[arg(long, value_name = "SECS", default_value_t = 5.0, value_parser = troupe_node::args::seconds)]
    pub timeout: f64,
}

impl Message {
    /// The device, the schema of the message and its payload.
    fn resolve(&self, command: bool) -> anyhow::Result<(Device, &'static str, Value, Vec<u8>)> {
        let dev = device(&self.device, self.robot)?;
        let schema = schema_of(dev, command, &self.name)?;
        let msg = message(schema, self.json.as_deref(), &self.values)?;
        let payload = encode(schema, &msg)?;
        Ok((dev, schema, msg, payload))
    }
}

/// The schema of command (or request) `name` of `dev`, or an error listing
/// what the device takes.
fn schema_of(dev: Device, command: bool, name: &str) -> anyhow::Result<&'static str> {
    let routes = routed(dev.interface);
    let found = routes.iter().find(|(r, _)| match r {
        Route::Command(n) => command && *n == name,
        Route::Request(n) => !command && *n == name,
    });
    if let Some((_, schema)) = found {
        return Ok(schema);
    }
    let names = |cmd: bool| -> String {
        let v: Vec<&str> = routes
            .iter()
            .filter_map(|(r, _)| match (r, cmd) {
                (Route::Command(n), true) | (Route::Request(n), false) => Some(*n),
                _ => None,
            })
            .collect();
        if v.is_empty() {
            "none".to_owned()
        } else {
            v.join(", ")
        }
    };
    let what = if command { "command" } else { "request" };
    anyhow::bail!(
        "{} has no {what} `{name}`; its commands (`troupe cmd`): {}; its requests (`troupe call`): {}",
        dev.interface,
        names(true),
        names(false)
    )
}

/// A JSON value whose objects keep their fields in the order the message
/// declares them (serde_json's map sorts them): what positional values fill.
enum Ordered {
    Leaf(Value),
    Object(Vec<(String, Ordered)>),
    Array(Vec<Ordered>),
}

impl<'de> serde::Deserialize<'de> for Ordered {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> serde::de::Visitor<'de> for V {
            type Value = Ordered;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("a JSON value")
            }
            fn visit_bool<E>(self, b: bool) -> Result<Ordered, E> {
                Ok(Ordered::Leaf(Value::Bool(b)))
            }
            fn visit_i64<E>(self, n: i64) -> Result<Ordered, E> {
                Ok(Ordered::Leaf(Value::from(n)))
            }
            fn visit_u64<E>(self, n: u64) -> Result<Ordered, E> {
                Ok(Ordered::Leaf(Value::from(n)))
            }
            fn visit_f64<E>(self, n: f64) -> Result<Ordered, E> {
                Ok(Ordered::Leaf(Value::from(n)))
            }
            fn visit_str<E>(self, s: &str) -> Result<Ordered, E> {
                Ok(Ordered::Leaf(Value::from(s)))
            }
            fn visit_unit<E>(self) -> Result<Ordered, E> {
                Ok(Ordered::Leaf(Value::Null))
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(
                self,
                mut a: A,
            ) -> Result<Ordered, A::Error> {
                let mut v = Vec::new();
                while let Some(x) = a.next_element()? {
                    v.push(x);
                }
                Ok(Ordered::Array(v))
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                mut a: A,
            ) -> Result<Ordered, A::Error> {
                let mut v = Vec::new();
                while let Some(kv) = a.next_entry()? {
                    v.push(kv);
                }
                Ok(Ordered::Object(v))
            }
        }
        d.deserialize_any(V)
    }
}

impl Ordered {
    /// Fills the leaves (depth first, in field order) from `values`.
    fn fill(
        &mut self,
        path: &str,
        values: &mut std::slice::Iter<'_, String>,
    ) -> anyhow::Result<()> {
        match self {
            Ordered::Object(fields) => {
                for (k, child) in fields {
                    let p = if path.is_empty() {
                        k.clone()
                    } else {
                        format!("{path}.{k}")
                    };
                    child.fill(&p, values)?;
                }
            }
            Ordered::Array(items) => {
                for (i, child) in items.iter_mut().enumerate() {
                    child.fill(&format!("{path}[{i}]"), values)?;
                }
            }
            Ordered::Leaf(leaf) => {
                let Some(text) = values.next() else {
                    return Ok(());
                };
                *leaf = match leaf {
                    Value::Bool(_) => Value::Bool(match text.as_str() {
                        "true" | "1" | "on" | "yes" => true,
                        "false" | "0" | "off" | "no" => false,
                        _ => anyhow::bail!("`{text}` is not true or false ({path})"),
                    }),
                    Value::Number(_) => {
                        let x: f64 = text
                            .parse()
                            .map_err(|_| anyhow::anyhow!("`{text}` is not a number ({path})"))?;
                        serde_json::Number::from_f64(x)
                            .map(Value::Number)
                            .with_context(|| format!("`{text}` is not a finite number ({path})"))?
                    }
                    _ => Value::String(text.clone()),
                };
            }
        }
        Ok(())
    }

    fn into_value(self) -> Value {
        match self {
            Ordered::Leaf(v) => v,
            Ordered::Array(items) => {
                Value::Array(items.into_iter().map(Ordered::into_value).collect())
            }
            Ordered::Object(fields) => Value::Object(
                fields
                    .into_iter()
                    .map(|(k, v)| (k, v.into_value()))
                    .collect(),
            ),
        }
    }
}

/// The message of `schema` from `--json` or from positional values.
fn message(schema: &str, json: Option<&str>, values: &[String]) -> anyhow::Result<Value> {
    if let Some(j) = json {
        return serde_json::from_str(j).context("--json is not JSON");
    }
    let mut text = Vec::new();
    default_of(schema, &mut serde_json::Serializer::new(&mut text))
        .with_context(|| format!("no message `{schema}`"))??;
    let mut v: Ordered = serde_json::from_slice(&text)?;
    let mut it = values.iter();
    v.fill("", &mut it)?;
    let v = v.into_value();
    let extra: Vec<&String> = it.collect();
    if !extra.is_empty() {
        anyhow::bail!(
            "{} more values than `{schema}` has fields ({v}): {extra:?}",
            extra.len()
        );
    }
    Ok(v)
}

fn encode(schema: &str, v: &Value) -> anyhow::Result<Vec<u8>> {
    encode_from(schema, v, troupe_client::now())
        .map_err(|e| anyhow::anyhow!("not a `{schema}`: {e} (its fields: {})", fields(schema)))?
        .with_context(|| format!("no message `{schema}`"))
}

fn fields(schema: &str) -> String {
    default_of(schema, serde_json::value::Serializer)
        .and_then(Result::ok)
        .map_or_else(String::new, |v| v.to_string())
}

fn device(text: &str, robot: u32) -> anyhow::Result<Device> {
    let a: DevAddr = text.parse()?;
    Ok(a.device(robot))
}

/// `troupe cmd`.
pub fn cmd(a: CmdArgs, z: &ZenohArgs) -> anyhow::Result<()> {
    let (dev, schema, msg, payload) = a.message.resolve(true)?;
    let name = &a.message.name;
    let motion = matches!(
        schema.split_once('@').map(|(k, _)| k),
        Some("position2d/cmd_vel" | "position2d/cmd_car")
    );
    anyhow::ensure!(
        a.rate.is_finite() && a.rate > 0.0,
        "--rate must be a positive number of sends per second"
    );
    let client = Client::connect(z, dev.robot)?;
    let held = a.seconds.is_some() || motion;
    if !held {
        client.command_payload(dev, name, payload)?;
        eprintln!("troupe cmd: sent {} {msg} to {dev}", name);
        return Ok(());
    }
    let stop = troupe_node::process::stop_flag().context("catching Ctrl-C")?;
    let until = a
        .seconds
        .map(|s| Instant::now() + Duration::from_secs_f64(s.max(0.0)));
    eprintln!(
        "troupe cmd: sending {} {msg} to {dev} {} times a second {}",
        name,
        a.rate,
        match a.seconds {
            Some(s) => format!("for {s} s"),
            None => "until Ctrl-C".to_owned(),
        }
    );
    let period = Duration::from_secs_f64(1.0 / a.rate);
    let mut next = Instant::now();
    while !stop.load(Ordering::Relaxed) && until.is_none_or(|u| Instant::now() < u) {
        client.command_payload(dev, name, payload.clone())?;
        next += period;
        // Pacing a repeated command, not synchronising: sleep to the next send.
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
    if motion {
        let zero = default_of(schema, serde_json::value::Serializer)
            .with_context(|| format!("no message `{schema}`"))??;
        client.command_payload(dev, name, encode(schema, &zero)?)?;
        eprintln!("troupe cmd: stopped {dev}");
    }
    Ok(())
}

/// `troupe call`.
pub fn call(a: CallArgs, z: &ZenohArgs) -> anyhow::Result<()> {
    let (dev, _, _, payload) = a.message.resolve(false)?;
    let name = &a.message.name;
    let timeout = Duration::try_from_secs_f64(a.timeout)
        .map_err(|_| anyhow::anyhow!("--timeout must be seconds ≥ 0"))?;
    let session = z.open(Mode::Client)?;
    let client = Client::with_session(session, dev.robot);
    let reply = match client.request_payload(dev, name, payload, timeout) {
        Ok(r) => r,
        Err(e @ (ClientError::Nack { .. } | ClientError::NoAnswer { .. })) => {
            anyhow::bail!("{e}")
        }
        Err(e) => return Err(e.into()),
    };
    let got = decode_any(&reply).with_context(|| format!("the answer of {dev} to `{}`", name))?;
    let mut body = Vec::new();
    got.msg
        .serialize_body(&mut serde_json::Serializer::new(&mut body))?;
    let kind = got.msg.schema();
    let text = String::from_utf8_lossy(&body);
    let mut out = std::io::stdout().lock();
    if text == "null" {
        writeln!(out, "{kind}")?;
    } else {
        writeln!(out, "{kind} {text}")?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use troupe_msgs::{position2d, simulation, Interface, Message};

    fn dev(i: Interface) -> Device {
        Device::new(6665, i, 0)
    }

    #[test]
    fn values_fill_the_fields_in_order_and_the_rest_keep_defaults() {
        let v = message(
            position2d::CmdVel::SCHEMA,
            None,
            &["0.3".into(), "0".into(), "-0.2".into()],
        )
        .unwrap();
        assert_eq!(v["vel"]["x"], 0.3);
        assert_eq!(v["vel"]["yaw"], -0.2);
        assert_eq!(v["state"], false);
        let v = message(simulation::GetPose2d::SCHEMA, None, &["r0".into()]).unwrap();
        let bytes = encode(simulation::GetPose2d::SCHEMA, &v).unwrap();
        let back = troupe_msgs::decode::<simulation::GetPose2d>(&bytes).unwrap();
        assert_eq!(back.msg.name, "r0");
    }

    #[test]
    fn bad_values_say_which_field() {
        let e = message(position2d::CmdVel::SCHEMA, None, &["fast".into()]).unwrap_err();
        assert_eq!(e.to_string(), "`fast` is not a number (vel.x)");
        let too_many: Vec<String> = ["1", "0", "0", "on", "9"].map(String::from).to_vec();
        let e = message(position2d::CmdVel::SCHEMA, None, &too_many).unwrap_err();
        assert!(e.to_string().starts_with("1 more values than"), "{e}");
        let e = encode(position2d::CmdVel::SCHEMA, &serde_json::json!({"vel": 1})).unwrap_err();
        assert!(e.to_string().contains("its fields"), "{e}");
    }

    #[test]
    fn a_wrong_name_lists_what_the_device_takes() {
        let e = schema_of(dev(Interface::Position2d), true, "velo").unwrap_err();
        let text = e.to_string();
        assert!(
            text.starts_with(
                "position2d has no command `velo`; its commands (`troupe cmd`): vel, pos, car;"
            ),
            "{text}"
        );
        assert!(text.contains("geom") && text.contains("power"), "{text}");
        assert_eq!(
            schema_of(dev(Interface::Planner), true, "goal").unwrap(),
            troupe_msgs::planner::Goal::SCHEMA
        );
    }
}
