//! Recordings of Foxglove's messages (`--format foxglove`): each sample
//! becomes the messages the live Foxglove server would send for it
//! (troupe-foxglove-msgs), protobuf on channels of Foxglove's own schemas,
//! JSON for the rest, so a file plays in Foxglove as the live connection
//! looked.

use std::collections::{BTreeMap, HashMap};

use troupe_foxglove_msgs::foxglove;
use troupe_foxglove_msgs::Translator;
use troupe_msgs::decode_any;
use troupe_ros2::stamp_ns;

use crate::ros2::{lines, JSON, KEPT, UNREADABLE};
use crate::{Files, Schema};

/// The MCAP profile of Foxglove's files (none: any channel may hold any
/// schema).
pub const PROFILE: &str = "";

/// A topic's schema, and how many messages of each kind of sample it took.
struct Topic {
    schema: Option<foxglove::Schema>,
    from: Vec<(&'static str, u64)>,
}

/// Writes samples as Foxglove messages, and counts what went where.
#[derive(Default)]
pub struct Foxglove {
    translator: Translator,
    topics: HashMap<String, Topic>,
    /// (schema tag, why) -> samples that made no message.
    kept: BTreeMap<(&'static str, &'static str), u64>,
}

impl Foxglove {
    /// A writer that has seen nothing yet.
    pub fn new() -> Foxglove {
        Foxglove::default()
    }

    /// Writes the Foxglove messages of one recorded sample, `payload` on
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
            *self.kept.entry(("?", UNREADABLE)).or_default() += 1;
            return Ok(());
        };
        let tag = s.msg.schema();
        let stamp = stamp_ns(s.stamp);
        let out = self.translator.translate(key, stamp, &s.msg);
        if out.is_empty() {
            *self.kept.entry((tag, KEPT)).or_default() += 1;
        }
        for m in out {
            let topic = match self.topics.get_mut(&m.topic) {
                Some(t) => t,
                None => self.topics.entry(m.topic.clone()).or_insert(Topic {
                    schema: m.kind.schema(),
                    from: Vec::new(),
                }),
            };
            let schema = topic.schema.as_ref().map_or(
                Schema {
                    name: "",
                    encoding: "",
                    data: &[],
                },
                |s| Schema {
                    name: &s.name,
                    encoding: &s.encoding,
                    data: &s.data,
                },
            );
            files.write(
                &m.topic,
                schema,
                m.kind.encoding(),
                &m.data,
                log_time,
                stamp,
            )?;
            match topic.from.iter_mut().find(|(t, _)| *t == tag) {
                Some((_, n)) => *n += 1,
                None => topic.from.push((tag, 1)),
            }
        }
        Ok(())
    }

    /// What went where, a line per sample kind and what it became:
    /// `laser/scan@1 -> foxglove.LaserScan  1200`.
    pub fn summary(&self) -> String {
        let mut counts: BTreeMap<(&str, &str), u64> = BTreeMap::new();
        for t in self.topics.values() {
            let to = match &t.schema {
                Some(s) if s.encoding == "jsonschema" => JSON,
                Some(s) => s.name.as_str(),
                None => "?",
            };
            for &(tag, n) in &t.from {
                *counts.entry((tag, to)).or_default() += n;
            }
        }
        for (&(tag, why), &n) in &self.kept {
            *counts.entry((tag, why)).or_default() += n;
        }
        lines(counts.iter().map(|(&(tag, to), &n)| (tag, to, n)))
    }
}

impl Foxglove {
    /// Messages written as JSON, for want of a Foxglove schema.
    pub fn json_count(&self) -> u64 {
        self.topics
            .values()
            .filter(|t| {
                t.schema
                    .as_ref()
                    .is_some_and(|s| s.encoding == "jsonschema")
            })
            .flat_map(|t| t.from.iter().map(|&(_, n)| n))
            .sum()
    }
}
