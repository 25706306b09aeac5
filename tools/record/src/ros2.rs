//! Recordings of ROS 2 messages (`--format ros2`): each sample becomes the
//! ROS 2 messages that carry it (troupe-ros2 says which), CDR on channels
//! of `ros2msg` schemas, as rosbag2 writes MCAP. A sample with no ROS 2
//! form is written as JSON (schema encoding `jsonschema`), never dropped;
//! [`Ros2::summary`] says what went where.

use std::collections::{BTreeMap, HashMap};

use troupe_msgs::decode_any;
use troupe_ros2::{json_schema, json_topic, stamp_ns, topic_of_key, Translator, Type};

use crate::{Files, Schema};

/// The MCAP profile of a bag of ROS 2 messages.
pub const PROFILE: &str = "ros2";
/// The message encoding of ROS 2 messages.
pub const CDR: &str = "cdr";

/// Where a sample went when it was not written as a ROS 2 message.
const KEPT: &str = "(kept: the shape of later messages)";
const JSON: &str = "JSON";
const UNREADABLE: &str = "(unreadable: left out)";

/// Writes samples as ROS 2 messages, and counts what went where.
#[derive(Default)]
pub struct Ros2 {
    translator: Translator,
    definitions: HashMap<Type, String>,
    json_schemas: HashMap<&'static str, String>,
    /// (schema tag, what it became) -> messages.
    counts: BTreeMap<(&'static str, &'static str), u64>,
}

impl Ros2 {
    /// A writer that has seen nothing yet.
    pub fn new() -> Ros2 {
        Ros2::default()
    }

    /// Writes the ROS 2 messages of one recorded sample, `payload` on
    /// `key`, received at `log_time` (ns since the epoch).
    ///
    /// # Errors
    ///
    /// The file cannot be written.
    pub fn write(
        &mut self,
        files: &mut Files,
        key: &str,
        payload: &[u8],
        log_time: u64,
    ) -> anyhow::Result<()> {
        let Ok(s) = decode_any(payload) else {
            *self.counts.entry(("?", UNREADABLE)).or_default() += 1;
            return Ok(());
        };
        let tag = s.msg.schema();
        let stamp = stamp_ns(s.stamp);
        let Some(outs) = self.translator.translate(key, stamp, &s.msg) else {
            let mut json = Vec::new();
            s.msg
                .serialize_body(&mut serde_json::Serializer::new(&mut json))?;
            let schema = self
                .json_schemas
                .entry(tag)
                .or_insert_with(|| json_schema(tag));
            let schema = Schema {
                name: tag,
                encoding: "jsonschema",
                data: schema.as_bytes(),
            };
            let topic = json_topic(&topic_of_key(key), tag);
            files.write(&topic, schema, "json", &json, log_time, stamp)?;
            *self.counts.entry((tag, JSON)).or_default() += 1;
            return Ok(());
        };
        if outs.is_empty() {
            *self.counts.entry((tag, KEPT)).or_default() += 1;
        }
        for o in outs {
            let definition = self
                .definitions
                .entry(o.ty)
                .or_insert_with(|| o.ty.definition());
            let schema = Schema {
                name: o.ty.name(),
                encoding: "ros2msg",
                data: definition.as_bytes(),
            };
            files.write(&o.topic, schema, CDR, &o.data, log_time, stamp)?;
            *self.counts.entry((tag, o.ty.name())).or_default() += 1;
        }
        Ok(())
    }

    /// What went where, a line per sample kind and what it became:
    /// `laser/scan@1 -> sensor_msgs/msg/LaserScan  1200`.
    pub fn summary(&self) -> String {
        lines(self.counts.iter().map(|(&(tag, to), &n)| (tag, to, n)))
    }

    /// Messages written as JSON, for want of a ROS 2 form.
    pub fn json_count(&self) -> u64 {
        self.counts
            .iter()
            .filter(|((_, to), _)| *to == JSON)
            .map(|(_, n)| n)
            .sum()
    }
}

/// A summary's lines: `  laser/scan@1 -> sensor_msgs/msg/LaserScan  1200`.
pub(crate) fn lines<'a>(counts: impl Iterator<Item = (&'a str, &'a str, u64)>) -> String {
    let mut s = String::new();
    for (tag, to, n) in counts {
        s.push_str(&format!("  {tag:<28} -> {to:<44} {n:>8}\n"));
    }
    s
}
