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

/// Where a sample went when it was not written as a ROS 2 (or Foxglove)
/// message; the Foxglove writer's summary says the same.
pub(crate) const KEPT: &str = "(kept: the shape of later messages)";
pub(crate) const JSON: &str = "JSON";
pub(crate) const UNREADABLE: &str = "(unreadable: left out)";
/// ROS 2 messages heard on the router, in a summary.
const ROS2: &str = "(ROS 2, as sent)";
const UNKNOWN_TYPE: &str = "(a ROS 2 type Troupe has no definition of: left out)";

/// The header stamp of a ROS 2 message of type `t` whose first field is a
/// `std_msgs/Header` (its first 8 bytes after CDR's 4), in nanoseconds.
fn header_stamp(t: Type, cdr: &[u8]) -> Option<u64> {
    let headed = !matches!(t, Type::TfMessage | Type::String | Type::Twist);
    let b = cdr.get(4..12).filter(|_| headed)?;
    let sec = i32::from_le_bytes(b[..4].try_into().ok()?);
    let nanosec = u32::from_le_bytes(b[4..].try_into().ok()?);
    Some(troupe_ros2::msg::Time { sec, nanosec }.ns())
}

/// True for a key of ROS 2 traffic (rmw_zenoh's form), recorded as the
/// ROS 2 message it carries whatever the format.
pub fn is_ros2(key: &str) -> bool {
    troupe_ros2::rmw::parse_key(key).is_some()
}

/// Writes samples as ROS 2 messages, and counts what went where.
#[derive(Default)]
pub struct Ros2 {
    translator: Translator,
    definitions: HashMap<Type, String>,
    json_schemas: HashMap<&'static str, String>,
    /// (schema tag, what it became) -> messages.
    counts: BTreeMap<(&'static str, &'static str), u64>,
    /// JSON as `std_msgs/msg/String`, for a rosbag2 directory (whose
    /// readers take CDR only).
    strings: bool,
    /// Each topic's type, encoding and messages (a rosbag2 directory's
    /// metadata).
    topics: BTreeMap<String, (&'static str, &'static str, u64)>,
    /// The first and last log times.
    span: Option<(u64, u64)>,
}

impl Ros2 {
    /// A writer that has seen nothing yet.
    pub fn new() -> Ros2 {
        Ros2::default()
    }

    /// A writer for a rosbag2 directory: what has no ROS 2 form goes as
    /// its JSON in a `std_msgs/msg/String`, CDR like the rest.
    pub fn for_rosbag2() -> Ros2 {
        Ros2 {
            strings: true,
            ..Ros2::default()
        }
    }

    /// Counts one message on `topic` for the metadata.
    fn count(&mut self, topic: &str, ty: &'static str, encoding: &'static str, log_time: u64) {
        match self.topics.get_mut(topic) {
            Some(t) => t.2 += 1,
            None => {
                self.topics.insert(topic.to_owned(), (ty, encoding, 1));
            }
        }
        let (lo, hi) = self.span.unwrap_or((log_time, log_time));
        self.span = Some((lo.min(log_time), hi.max(log_time)));
    }

    /// A rosbag2 directory's `metadata.yaml` (version 4, storage `mcap`)
    /// for what was written, in `files` (names relative to the directory).
    pub fn metadata(&self, files: &[String]) -> String {
        let (start, end) = self.span.unwrap_or((0, 0));
        let total: u64 = self.topics.values().map(|t| t.2).sum();
        let mut y = format!(
            "rosbag2_bagfile_information:\n  version: 4\n  storage_identifier: mcap\n  \
             duration:\n    nanoseconds: {}\n  starting_time:\n    nanoseconds_since_epoch: {start}\n  \
             message_count: {total}\n  topics_with_message_count:\n",
            end - start
        );
        for (name, (ty, encoding, n)) in &self.topics {
            y.push_str(&format!(
                "    - topic_metadata:\n        name: {name}\n        type: {ty}\n        \
                 serialization_format: {encoding}\n        offered_qos_profiles: \"\"\n      \
                 message_count: {n}\n"
            ));
        }
        y.push_str(
            "  compression_format: \"\"\n  compression_mode: \"\"\n  relative_file_paths:\n",
        );
        for f in files {
            y.push_str(&format!("    - {f}\n"));
        }
        y
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
        // ROS 2 traffic on the router (rmw_zenoh's keys): already CDR.
        if let Some((_, topic, ty)) = troupe_ros2::rmw::parse_key(key) {
            return match Type::from_name(&ty) {
                Some(t) => {
                    let stamp = header_stamp(t, payload).unwrap_or(log_time);
                    self.put(files, ROS2, &topic, t, payload, log_time, stamp)
                }
                None => {
                    *self.counts.entry((ROS2, UNKNOWN_TYPE)).or_default() += 1;
                    Ok(())
                }
            };
        }
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
            let topic = json_topic(&topic_of_key(key), tag);
            if self.strings {
                let text = troupe_ros2::msg::Text {
                    data: String::from_utf8_lossy(&json).into_owned(),
                };
                let ty = Type::String;
                return self.put(
                    files,
                    tag,
                    &topic,
                    ty,
                    &troupe_ros2::cdr(&text),
                    log_time,
                    stamp,
                );
            }
            let schema = self
                .json_schemas
                .entry(tag)
                .or_insert_with(|| json_schema(tag));
            let schema = Schema {
                name: tag,
                encoding: "jsonschema",
                data: schema.as_bytes(),
            };
            files.write(&topic, schema, "json", &json, log_time, stamp)?;
            self.count(&topic, tag, "json", log_time);
            *self.counts.entry((tag, JSON)).or_default() += 1;
            return Ok(());
        };
        if outs.is_empty() {
            *self.counts.entry((tag, KEPT)).or_default() += 1;
        }
        for o in outs {
            self.put(files, tag, &o.topic, o.ty, &o.data, log_time, stamp)?;
        }
        Ok(())
    }

    /// Writes one ROS 2 message, made of a sample of kind `tag`.
    #[allow(clippy::too_many_arguments)]
    fn put(
        &mut self,
        files: &mut Files,
        tag: &'static str,
        topic: &str,
        ty: Type,
        data: &[u8],
        log_time: u64,
        stamp: u64,
    ) -> anyhow::Result<()> {
        let definition = self
            .definitions
            .entry(ty)
            .or_insert_with(|| ty.definition());
        let schema = Schema {
            name: ty.name(),
            encoding: "ros2msg",
            data: definition.as_bytes(),
        };
        files.write(topic, schema, CDR, data, log_time, stamp)?;
        self.count(topic, ty.name(), CDR, log_time);
        *self.counts.entry((tag, ty.name())).or_default() += 1;
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
