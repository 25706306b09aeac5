//! `troupe record`, `troupe play` and `troupe log`: a fleet's samples in MCAP,
//! the container rosbag2 and Foxglove read.
//!
//! One MCAP channel per key and schema tag (a ranger's ranges and
//! intensities share a key); the message bytes are the sample's payload
//! exactly as it travelled (schema tag, stamp, postcard body). A message's
//! `log_time` is when the recorder received it (ns since the Unix epoch),
//! its `publish_time` the sample's own stamp (ns; simulation time under a
//! simulator). Devices' liveliness goes on channels of encoding
//! `troupe/liveliness` (one byte: 1 = came, 0 = went), so a replay can say
//! which drivers provided what, and declares those devices live again.

use std::collections::{BTreeMap, HashMap};
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, Sender, SyncSender};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime};

use anyhow::Context;
use clap::{Args, Subcommand, ValueEnum};
use troupe_msgs::{codec, decode_any, keys, Device};
use troupe_node::zenoh::{pubsub::Subscriber, sample::SampleKind, Session, Wait};
use troupe_node::{Mode, ZenohArgs};

pub mod foxglove;
pub mod ros2;

/// The message encoding of recorded samples.
pub const ENCODING: &str = "troupe/postcard";
/// The message encoding of liveliness events.
pub const LIVELINESS: &str = "troupe/liveliness";

/// Flags of `troupe record`.
#[derive(Debug, Args)]
pub struct RecordArgs {
    /// Key expressions to record (default: every device's data, `robot/*/*/*`,
    /// and the simulation clock, `sim/clock`). ROS 2 traffic on the router
    /// (rmw_zenoh's keys: `0/**` for domain 0) is written as the ROS 2
    /// messages it carries, on their topics.
    pub keys: Vec<String>,
    /// The file to write (with splitting: NAME_0.mcap, NAME_1.mcap, …).
    #[arg(short = 'o', long, value_name = "FILE", default_value = "troupe.mcap")]
    pub output: PathBuf,
    /// Stop after this many seconds (default: at Ctrl-C or SIGTERM).
    #[arg(long, value_name = "SECS", value_parser = troupe_node::args::seconds)]
    pub duration: Option<f64>,
    /// Start a new file after this many megabytes.
    #[arg(long, value_name = "MB", value_parser = troupe_node::args::finite)]
    pub split_size: Option<f64>,
    /// Start a new file after this many seconds.
    #[arg(long, value_name = "SECS", value_parser = troupe_node::args::seconds)]
    pub split_duration: Option<f64>,
    /// Compress chunks.
    #[arg(long, value_enum, default_value_t = Compress::None)]
    pub compress: Compress,
    /// Samples waiting for the disk before the recorder drops (and counts) new ones.
    #[arg(long, value_name = "N", default_value_t = 100_000)]
    pub queue: usize,
    /// `troupe`: every sample byte for byte (`troupe play` replays it);
    /// `ros2`: ROS 2 messages (CDR) that ros2 bag, rosbags, PlotJuggler and
    /// Foxglove read; `foxglove`: Foxglove's own schemas (protobuf), as
    /// `troupe foxglove` shows them live (`troupe log export` converts
    /// later).
    #[arg(long, value_enum, default_value_t = RecordFormat::Troupe)]
    pub format: RecordFormat,
    /// Write a rosbag2 directory instead of one file: `-o` names the
    /// directory (made; it must not hold anything), which gets the MCAP
    /// file(s) and the `metadata.yaml` `ros2 bag info` reads. ROS 2
    /// messages (implies `--format ros2`); what has no ROS 2 form goes as
    /// its JSON in a `std_msgs/msg/String`.
    #[arg(long)]
    pub rosbag2: bool,
}

/// What `troupe record` writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum RecordFormat {
    /// Troupe's samples as they travelled.
    Troupe,
    /// ROS 2 messages.
    Ros2,
    /// Foxglove's messages.
    Foxglove,
}

/// Chunk compression.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Compress {
    /// None: the fastest to write.
    None,
    /// zstd, as rosbag2 and Foxglove write.
    Zstd,
}

/// Flags of `troupe play`.
#[derive(Debug, Args)]
pub struct PlayArgs {
    /// An MCAP file written by `troupe record`, or a ROS 2 bag's MCAP.
    pub file: PathBuf,
    /// Speed: 2 plays twice as fast as recorded; 0 as fast as the network takes it.
    #[arg(long, value_name = "X", default_value_t = 1.0, value_parser = troupe_node::args::finite)]
    pub rate: f64,
    /// Skip the first SECS of the recording.
    #[arg(long, value_name = "SECS", default_value_t = 0.0, value_parser = troupe_node::args::seconds)]
    pub start: f64,
    /// Stop SECS into the recording.
    #[arg(long, value_name = "SECS", value_parser = troupe_node::args::seconds)]
    pub end: Option<f64>,
    /// Start again at the end, until Ctrl-C.
    #[arg(long = "loop")]
    pub repeat: bool,
    /// Play only the keys this key expression matches (repeatable), e.g.
    /// `robot/6665/laser/0` or `robot/*/position2d/*`; default: all.
    #[arg(long, value_name = "KEYEXPR")]
    pub only: Vec<String>,
    /// Publish robot FROM's keys as robot TO's, e.g. `6665=7000`, or a ROS 2
    /// bag's topic on a device's key, e.g. `/scan=robot/6665/laser/0`
    /// (repeatable).
    #[arg(long, value_name = "FROM=TO")]
    pub remap: Vec<String>,
}

/// `troupe log …`.
#[derive(Debug, Subcommand)]
pub enum LogCmd {
    /// What a recording holds: duration, devices, messages and rates, size.
    Info {
        /// An MCAP file written by `troupe record`.
        file: PathBuf,
    },
    /// A recording as JSON lines, a Player text log, or ROS 2 messages.
    Export {
        /// An MCAP file written by `troupe record`.
        file: PathBuf,
        /// `json`: one object per message; `player`: Player's text log
        /// format; `ros2`: MCAP of ROS 2 messages; `foxglove`: MCAP of
        /// Foxglove's messages.
        #[arg(long, value_enum, default_value_t = Format::Json)]
        format: Format,
        /// The file to write (default: standard output; `ros2` and
        /// `foxglove` are MCAP and need one).
        #[arg(short = 'o', long, value_name = "FILE")]
        output: Option<PathBuf>,
        /// Write a rosbag2 directory (`-o DIR`: the MCAP file and the
        /// `metadata.yaml` `ros2 bag info` reads); implies `--format ros2`.
        #[arg(long)]
        rosbag2: bool,
    },
}

/// Export formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Format {
    /// One JSON object per line: time, key, stamp, the decoded message.
    Json,
    /// Player's text log (what readlog reads).
    Player,
    /// MCAP of ROS 2 messages (LaserScan, Odometry, TF…), as rosbag2 writes.
    Ros2,
    /// MCAP of Foxglove's messages (LaserScan, Grid, SceneUpdate…), as the
    /// live server sends them.
    Foxglove,
}

/// Samples written as another ecosystem's messages.
enum Converter {
    Ros2(ros2::Ros2),
    Foxglove(foxglove::Foxglove),
}

impl Converter {
    fn ros2() -> Converter {
        Converter::Ros2(ros2::Ros2::new())
    }

    fn rosbag2() -> Converter {
        Converter::Ros2(ros2::Ros2::for_rosbag2())
    }

    fn foxglove() -> Converter {
        Converter::Foxglove(foxglove::Foxglove::new())
    }

    fn profile(&self) -> &'static str {
        match self {
            Converter::Ros2(_) => ros2::PROFILE,
            Converter::Foxglove(_) => foxglove::PROFILE,
        }
    }

    /// "ROS 2", "Foxglove".
    fn name(&self) -> &'static str {
        match self {
            Converter::Ros2(_) => "ROS 2",
            Converter::Foxglove(_) => "Foxglove",
        }
    }

    fn write(&mut self, f: &mut Files, key: &str, payload: &[u8], at: u64) -> anyhow::Result<()> {
        match self {
            Converter::Ros2(w) => w.write(f, key, payload, at),
            Converter::Foxglove(w) => w.write(f, key, payload, at),
        }
    }

    fn summary(&self) -> String {
        match self {
            Converter::Ros2(w) => w.summary(),
            Converter::Foxglove(w) => w.summary(),
        }
    }

    /// A rosbag2 directory's metadata for `files` (ROS 2 only).
    fn metadata(&self, files: &[PathBuf]) -> Option<String> {
        let Converter::Ros2(w) = self else {
            return None;
        };
        let names: Vec<String> = files
            .iter()
            .filter_map(|f| f.file_name())
            .map(|f| f.to_string_lossy().into_owned())
            .collect();
        Some(w.metadata(&names))
    }

    fn json_count(&self) -> u64 {
        match self {
            Converter::Ros2(w) => w.json_count(),
            Converter::Foxglove(w) => w.json_count(),
        }
    }
}

fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}

/// What the recorder hears: a sample or a liveliness event.
enum Heard {
    Sample {
        key: String,
        payload: Vec<u8>,
        at: u64,
    },
    Token {
        key: String,
        came: bool,
        at: u64,
    },
}

impl Heard {
    /// When the recorder heard it, ns since the Unix epoch.
    fn at(&self) -> u64 {
        match self {
            Heard::Sample { at, .. } | Heard::Token { at, .. } => *at,
        }
    }
}

/// A channel's schema record: its name, encoding and text.
#[derive(Debug, Clone, Copy)]
pub struct Schema<'a> {
    /// The schema tag (`laser/scan@1`), or the ROS 2 type.
    pub name: &'a str,
    /// [`ENCODING`], [`LIVELINESS`], `ros2msg`, `jsonschema`.
    pub encoding: &'a str,
    /// The definition (none for Troupe's own: the tag names it).
    pub data: &'a [u8],
}

impl Schema<'_> {
    /// A Troupe schema: named by its tag, of `encoding`, no definition.
    pub fn troupe<'a>(name: &'a str, encoding: &'a str) -> Schema<'a> {
        Schema {
            name,
            encoding,
            data: &[],
        }
    }
}

/// The files of one recording and what is in them so far: one MCAP file,
/// or a series of them (`--split-size`, `--split-duration`).
pub struct Files {
    base: PathBuf,
    profile: &'static str,
    split: bool,
    compress: Compress,
    index: usize,
    writer: Option<mcap::Writer<std::io::BufWriter<std::fs::File>>>,
    path: PathBuf,
    opened_at: u64,
    bytes: u64,
    /// Channel ids by key, then by schema tag (a key has one or two).
    channels: HashMap<String, Vec<(String, u16)>>,
    sequence: HashMap<u16, u32>,
    written: Vec<PathBuf>,
}

impl Files {
    /// Bytes written to the current file so far.
    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    /// Every file started so far.
    pub fn written(&self) -> &[PathBuf] {
        &self.written
    }

    /// Nothing open yet: [`Files::open`] starts the first file.
    pub fn new(base: PathBuf, split: bool, compress: Compress) -> Files {
        Files {
            base,
            profile: "troupe",
            split,
            compress,
            index: 0,
            writer: None,
            path: PathBuf::new(),
            opened_at: 0,
            bytes: 0,
            channels: HashMap::new(),
            sequence: HashMap::new(),
            written: Vec::new(),
        }
    }

    /// Files of MCAP profile `profile` (`troupe` unless said: `ros2` for
    /// a bag of ROS 2 messages).
    pub fn with_profile(mut self, profile: &'static str) -> Files {
        self.profile = profile;
        self
    }

    /// Starts the next file, `at` ns since the epoch.
    ///
    /// # Errors
    ///
    /// The file cannot be created.
    pub fn open(&mut self, at: u64) -> anyhow::Result<()> {
        self.path = if self.split {
            let stem = self
                .base
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "troupe".into());
            self.base
                .with_file_name(format!("{stem}_{}.mcap", self.index))
        } else {
            self.base.clone()
        };
        self.index += 1;
        let f = std::fs::File::create(&self.path)
            .with_context(|| format!("creating {}", self.path.display()))?;
        let w = mcap::WriteOptions::new()
            .profile(self.profile)
            .compression(match self.compress {
                Compress::None => None,
                Compress::Zstd => Some(mcap::Compression::Zstd),
            })
            .create(std::io::BufWriter::new(f))
            .with_context(|| format!("writing {}", self.path.display()))?;
        self.writer = Some(w);
        self.opened_at = at;
        self.bytes = 0;
        self.channels.clear();
        self.sequence.clear();
        self.written.push(self.path.clone());
        Ok(())
    }

    /// Finishes the file being written (its summary and index).
    ///
    /// # Errors
    ///
    /// The file cannot be written.
    pub fn close(&mut self) -> anyhow::Result<()> {
        if let Some(mut w) = self.writer.take() {
            w.finish()
                .with_context(|| format!("finishing {}", self.path.display()))?;
        }
        Ok(())
    }

    /// Writes one message on the channel of `key` and `schema` (allocating
    /// only for a channel's first message: this runs for every sample).
    ///
    /// # Errors
    ///
    /// The file cannot be written.
    pub fn write(
        &mut self,
        key: &str,
        schema: Schema<'_>,
        encoding: &str,
        data: &[u8],
        log_time: u64,
        publish_time: u64,
    ) -> anyhow::Result<()> {
        let Files {
            writer,
            path,
            channels,
            sequence,
            bytes,
            ..
        } = self;
        let Some(w) = writer.as_mut() else {
            return Ok(());
        };
        let writing = || format!("writing {}", path.display());
        let known = channels
            .get(key)
            .and_then(|v| v.iter().find(|(s, _)| s == schema.name))
            .map(|&(_, id)| id);
        let id = match known {
            Some(id) => id,
            None => {
                let schema_id = w
                    .add_schema(schema.name, schema.encoding, schema.data)
                    .with_context(writing)?;
                let id = w
                    .add_channel(schema_id, key, encoding, &BTreeMap::new())
                    .with_context(writing)?;
                channels
                    .entry(key.to_owned())
                    .or_default()
                    .push((schema.name.to_owned(), id));
                id
            }
        };
        let seq = sequence.entry(id).or_default();
        *seq = seq.wrapping_add(1);
        w.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: id,
                sequence: *seq,
                log_time,
                publish_time,
            },
            data,
        )
        .with_context(writing)?;
        // The message record's own header is 31 bytes.
        *bytes += data.len() as u64 + 31;
        Ok(())
    }
}

/// `troupe record`.
pub fn record(a: RecordArgs, z: &ZenohArgs) -> anyhow::Result<()> {
    let exprs = if a.keys.is_empty() {
        vec![keys::data_all(), keys::SIM_CLOCK.to_owned()]
    } else {
        a.keys.clone()
    };
    // Caught from the start: a signal during set-up stops it cleanly too.
    let stop_rx = troupe_node::process::stop_receiver().context("catching Ctrl-C and SIGTERM")?;
    // A peer: the publishers' data comes straight from them where they
    // can be reached, not through the router's queue, where a simulator's
    // step bursts were dropped (a client lost 0.4-8% of the 100-Pioneer
    // world flat out; a peer loses none, at half the CPU).
    let session = z.open_peer()?;
    let (queue, rx) = Queue::new(a.queue);
    let listening = Listening::start(&session, &exprs, &queue)?;
    let dropped = queue.into_dropped();
    let split = a.split_size.is_some() || a.split_duration.is_some();
    announce(&exprs, &a.output, split)?;
    let writer = Writer::open(&a, split)?;
    let writer = std::thread::spawn(move || writer.run(rx));
    let started = Instant::now();
    let deadline = a
        .duration
        .map(|d| started + Duration::from_secs_f64(d.max(0.0)));
    wait_for_stop(&stop_rx, deadline, &dropped, a.queue);
    listening.stop();
    drop(session);
    let (files, count, bytes) = writer
        .join()
        .map_err(|_| anyhow::anyhow!("the recorder's writer thread panicked"))??;
    report(&files, count, bytes, started, &dropped)
}

/// The way to the writer: what a full queue has no room for is dropped and
/// counted.
#[derive(Clone)]
struct Queue {
    tx: SyncSender<Heard>,
    dropped: Arc<AtomicU64>,
}

impl Queue {
    /// A queue of `capacity` (one at least), and the writer's end of it.
    fn new(capacity: usize) -> (Queue, Receiver<Heard>) {
        let (tx, rx) = std::sync::mpsc::sync_channel::<Heard>(capacity.max(1));
        let dropped = Arc::new(AtomicU64::new(0));
        (Queue { tx, dropped }, rx)
    }

    /// Hands `h` to the writer, or counts it dropped when the queue is full.
    fn send(&self, h: Heard) {
        if self.tx.try_send(h).is_err() {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Lets this sender go (the writer ends when the listeners' go too),
    /// keeping the count of dropped samples.
    fn into_dropped(self) -> Arc<AtomicU64> {
        self.dropped
    }
}

/// What the recorder hears with: its subscriptions, the thread asking
/// arriving devices for their set-up, and the watch on liveliness.
struct Listening {
    subs: Vec<Subscriber<()>>,
    asker: JoinHandle<()>,
    tokens: Subscriber<()>,
}

impl Listening {
    /// Subscribes to `exprs`, starts the asker and watches liveliness, each
    /// sending what it hears to `queue`.
    fn start(session: &Session, exprs: &[String], queue: &Queue) -> anyhow::Result<Listening> {
        let subs = subscribe(session, exprs, queue)?;
        let (arrived, asker) = spawn_asker(session, queue);
        let tokens = watch_liveliness(session, arrived, queue)?;
        Ok(Listening {
            subs,
            asker,
            tokens,
        })
    }

    /// Stops hearing: the subscriptions, then the liveliness watch, whose end
    /// ends the asker, which is waited for.
    fn stop(self) {
        drop(self.subs);
        drop(self.tokens);
        let _ = self.asker.join();
    }
}

/// Subscribes to each of `exprs`, queueing every sample with when it came.
fn subscribe(
    session: &Session,
    exprs: &[String],
    queue: &Queue,
) -> anyhow::Result<Vec<Subscriber<()>>> {
    let mut subs = Vec::new();
    for e in exprs {
        let queue = queue.clone();
        let sub = session
            .declare_subscriber(e.as_str())
            .callback(move |s| {
                queue.send(Heard::Sample {
                    key: s.key_expr().as_str().to_owned(),
                    payload: s.payload().to_bytes().into_owned(),
                    at: now_ns(),
                });
            })
            .wait()
            .map_err(|err| anyhow::anyhow!("subscribing to {e}: {err}"))?;
        subs.push(sub);
    }
    Ok(subs)
}

/// Starts the thread that asks each device sent to it for its set-up,
/// queueing the answers as the device's samples.
fn spawn_asker(session: &Session, queue: &Queue) -> (Sender<Device>, JoinHandle<()>) {
    // What a Player client asks a device for once, asked as it comes: a
    // map's grid, a sensor's geometry and configuration. The answers are
    // recorded as samples of the device: they give a map to show and the
    // frames of the scans.
    let (arrived, asking) = std::sync::mpsc::channel::<Device>();
    let (queue, session) = (queue.clone(), session.clone());
    let asker = std::thread::spawn(move || {
        for dev in asking {
            for payload in troupe_node::setup_answers(&session, &dev) {
                queue.send(Heard::Sample {
                    key: keys::data(&dev),
                    payload,
                    at: now_ns(),
                });
            }
        }
    });
    (arrived, asker)
}

/// Watches devices come and go (those already live too), queueing each
/// event and sending each device that comes to the asker.
fn watch_liveliness(
    session: &Session,
    arrived: Sender<Device>,
    queue: &Queue,
) -> anyhow::Result<Subscriber<()>> {
    let queue = queue.clone();
    session
        .liveliness()
        .declare_subscriber(keys::all())
        .history(true)
        .callback(move |s| {
            let key = s.key_expr().as_str();
            let came = s.kind() == SampleKind::Put;
            if came {
                if let Ok((dev, _)) = keys::parse_token(key) {
                    let _ = arrived.send(dev);
                }
            }
            queue.send(Heard::Token {
                key: key.to_owned(),
                came,
                at: now_ns(),
            });
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("watching liveliness: {e}"))
}

/// Says what is recorded where.
fn announce(exprs: &[String], output: &Path, split: bool) -> anyhow::Result<()> {
    // On stdout, once every subscription is in place: a script (or a test)
    // may start what it records when this line appears.
    writeln!(
        std::io::stdout().lock(),
        "troupe record: {} to {}{} (Ctrl-C stops)",
        exprs.join(" "),
        output.display(),
        if split { " (split)" } else { "" }
    )?;
    Ok(())
}

/// The converter `--format` and `--rosbag2` ask for; none writes samples as
/// they travelled.
fn converter_for(format: RecordFormat, rosbag2: bool) -> anyhow::Result<Option<Converter>> {
    Ok(match (format, rosbag2) {
        (RecordFormat::Troupe | RecordFormat::Ros2, true) => Some(Converter::rosbag2()),
        (RecordFormat::Foxglove, true) => {
            anyhow::bail!("--rosbag2 is a directory of ROS 2 messages: not --format foxglove")
        }
        (RecordFormat::Troupe, false) => None,
        (RecordFormat::Ros2, false) => Some(Converter::ros2()),
        (RecordFormat::Foxglove, false) => Some(Converter::foxglove()),
    })
}

/// The writer thread: the recording's files, what converts the samples,
/// and what has been written.
struct Writer {
    files: Files,
    converter: Option<Converter>,
    /// Writes ROS 2 traffic as itself, among samples as they travelled.
    ros2_defs: ros2::Ros2,
    /// The rosbag2 directory (`--rosbag2`).
    bag: Option<PathBuf>,
    split_bytes: Option<u64>,
    split_ns: Option<u64>,
    count: u64,
    bytes: u64,
}

impl Writer {
    /// Opens the first file (in a new rosbag2 directory with `--rosbag2`),
    /// of the profile its converter writes.
    fn open(a: &RecordArgs, split: bool) -> anyhow::Result<Writer> {
        let bag = a.rosbag2.then(|| a.output.clone());
        let base = match &bag {
            Some(dir) => rosbag2_base(dir, split)?,
            None => a.output.clone(),
        };
        let mut files = Files::new(base, split, a.compress);
        let converter = converter_for(a.format, a.rosbag2)?;
        if let Some(c) = &converter {
            files = files.with_profile(c.profile());
        }
        files.open(now_ns())?;
        Ok(Writer {
            files,
            converter,
            ros2_defs: ros2::Ros2::new(),
            bag,
            split_bytes: a.split_size.map(|mb| (mb * 1e6) as u64),
            split_ns: a.split_duration.map(troupe_ros2::stamp_ns),
            count: 0,
            bytes: 0,
        })
    }

    /// Writes what comes until the listeners are gone, stopping at the first
    /// failure; then finishes, giving the files, messages and sample bytes.
    fn run(mut self, rx: Receiver<Heard>) -> anyhow::Result<(Files, u64, u64)> {
        let mut failed: Option<anyhow::Error> = None;
        for h in rx {
            if failed.is_some() {
                continue;
            }
            if let Err(e) = self.rotate_if_due(h.at()) {
                failed = Some(e);
                continue;
            }
            match self.write(&h) {
                Ok(true) => self.count += 1,
                Ok(false) => {}
                Err(e) => {
                    // Said at once; what was written before stays readable.
                    eprintln!(
                        "troupe record: {e:#}; recording stopped after {} messages",
                        self.count
                    );
                    let _ = self.files.close();
                    failed = Some(e);
                }
            }
        }
        if let Some(e) = failed {
            return Err(e);
        }
        self.finish()
    }

    /// Starts the next file, at `at`, once this one has its `--split-size`
    /// or `--split-duration`.
    fn rotate_if_due(&mut self, at: u64) -> anyhow::Result<()> {
        if self.split_bytes.is_some_and(|b| self.files.bytes >= b)
            || self
                .split_ns
                .is_some_and(|d| at.saturating_sub(self.files.opened_at) >= d)
        {
            self.files.close().and_then(|()| self.files.open(at))?;
        }
        Ok(())
    }

    /// Writes `h` as the format asks; false when it has no form there.
    fn write(&mut self, h: &Heard) -> anyhow::Result<bool> {
        let files = &mut self.files;
        match (h, self.converter.as_mut()) {
            (Heard::Sample { key, payload, at }, Some(w)) => {
                self.bytes += payload.len() as u64;
                w.write(files, key, payload, *at)?;
            }
            // Neither ROS 2 nor Foxglove has a form for a device's
            // coming and going.
            (Heard::Token { .. }, Some(_)) => return Ok(false),
            (Heard::Sample { key, payload, at }, None) if ros2::is_ros2(key) => {
                // ROS 2 traffic keeps its own form: CDR of its type.
                self.bytes += payload.len() as u64;
                self.ros2_defs.write(files, key, payload, *at)?;
            }
            (Heard::Sample { key, payload, at }, None) => {
                let (schema, stamp) = codec::split(payload).map_or(("?", 0), |(tag, stamp, _)| {
                    (tag, troupe_ros2::stamp_ns(stamp))
                });
                self.bytes += payload.len() as u64;
                files.write(
                    key,
                    Schema::troupe(schema, ENCODING),
                    ENCODING,
                    payload,
                    *at,
                    stamp,
                )?;
            }
            (Heard::Token { key, came, at }, None) => files.write(
                key,
                Schema::troupe("liveliness", LIVELINESS),
                LIVELINESS,
                &[u8::from(*came)],
                *at,
                *at,
            )?,
        }
        Ok(true)
    }

    /// Finishes the last file, a rosbag2 directory's metadata and the
    /// converter's summary.
    fn finish(mut self) -> anyhow::Result<(Files, u64, u64)> {
        self.files.close()?;
        if let Some(c) = self.converter {
            if let Some(dir) = &self.bag {
                write_metadata(dir, &self.files, &c)?;
            }
            eprint!("troupe record: as {} messages:\n{}", c.name(), c.summary());
        }
        Ok((self.files, self.count, self.bytes))
    }
}

/// Waits for a signal or the end of `--duration`, saying the drop count
/// as it grows.
fn wait_for_stop(
    stop_rx: &Receiver<()>,
    deadline: Option<Instant>,
    dropped: &AtomicU64,
    queue: usize,
) {
    let mut said = 0;
    loop {
        let tick = Duration::from_secs(1);
        let wait = deadline.map_or(tick, |d| {
            d.saturating_duration_since(Instant::now()).min(tick)
        });
        match stop_rx.recv_timeout(wait) {
            Ok(()) | Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => break,
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {}
        }
        let n = dropped.load(Ordering::Relaxed);
        if n > said {
            tracing::warn!(
                "the recorder is behind: {} samples dropped so far (--queue {} full)",
                n,
                queue
            );
            said = n;
        }
        if deadline.is_some_and(|d| Instant::now() >= d) {
            break;
        }
    }
}

/// Says what was recorded where; fails if samples were dropped.
fn report(
    files: &Files,
    count: u64,
    bytes: u64,
    started: Instant,
    dropped: &AtomicU64,
) -> anyhow::Result<()> {
    let secs = started.elapsed().as_secs_f64();
    let dropped = dropped.load(Ordering::Relaxed);
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "recorded {count} messages ({:.1} MB of samples) in {secs:.1} s to {}; {dropped} dropped",
        bytes as f64 / 1e6,
        files
            .written
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    )?;
    if dropped > 0 {
        anyhow::bail!("{dropped} samples were dropped: the disk did not keep up (a larger --queue, or --compress none, may)");
    }
    Ok(())
}

/// One message of a recording, as [`each_message`] hands it over.
pub struct Msg<'a> {
    /// The channel's topic: the sample's key.
    pub topic: &'a str,
    /// The channel's message encoding ([`ENCODING`] for samples).
    pub encoding: &'a str,
    /// The schema's name: the sample's schema tag.
    pub schema: &'a str,
    /// When the recorder received it, ns since the Unix epoch.
    pub log_time: u64,
    /// The sample's own stamp, ns.
    pub publish_time: u64,
    /// The payload as it travelled.
    pub data: &'a [u8],
}

/// Calls `each` on every message of a recording in file order, reading the
/// file a piece at a time (a large recording is never all in memory);
/// `each` returns false to stop. A damaged or cut file stops at the damage,
/// said once with how far the file was read; what came before has been
/// handed over.
pub fn each_message(
    path: &Path,
    mut each: impl FnMut(&Msg<'_>) -> anyhow::Result<bool>,
) -> anyhow::Result<()> {
    use mcap::records::Record;
    use mcap::sans_io::{LinearReadEvent, LinearReader};
    use std::io::Read as _;
    let name = path.display().to_string();
    let mut f = std::fs::File::open(path).with_context(|| format!("opening {name}"))?;
    let mut r = LinearReader::new();
    let mut schemas: HashMap<u16, String> = HashMap::new();
    let mut channels: HashMap<u16, (String, String, u16)> = HashMap::new();
    let mut read_so_far = 0u64;
    while let Some(event) = r.next_event() {
        let record = match event {
            Ok(LinearReadEvent::ReadRequest(n)) => {
                let read = f
                    .read(r.insert(n))
                    .with_context(|| format!("reading {name}"))?;
                read_so_far += read as u64;
                r.notify_read(read);
                continue;
            }
            Ok(LinearReadEvent::Record { data, opcode }) => mcap::parse_record(opcode, data),
            Err(e) => Err(e),
        };
        let record = match record {
            Ok(rec) => rec,
            Err(e) => {
                tracing::warn!(
                    "{name}: {e} (within its first {read_so_far} bytes); the rest is unreadable"
                );
                return Ok(());
            }
        };
        match record {
            Record::Schema { header, .. } => {
                schemas.insert(header.id, header.name);
            }
            Record::Channel(c) => {
                channels.insert(c.id, (c.topic, c.message_encoding, c.schema_id));
            }
            Record::Message { header, data } => {
                let Some((topic, encoding, schema)) = channels.get(&header.channel_id) else {
                    continue;
                };
                let m = Msg {
                    topic,
                    encoding,
                    schema: schemas.get(schema).map_or("", String::as_str),
                    log_time: header.log_time,
                    publish_time: header.publish_time,
                    data: &data,
                };
                if !each(&m)? {
                    return Ok(());
                }
            }
            _ => {}
        }
    }
    Ok(())
}

/// A recording's summary, read from its end without reading its messages.
fn summary(path: &Path) -> anyhow::Result<(u64, Option<mcap::Summary>)> {
    use mcap::sans_io::summary_reader::{SummaryReadEvent, SummaryReader, SummaryReaderOptions};
    use std::io::{Read as _, Seek as _};
    let mut f = std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let size = f.metadata()?.len();
    let mut r =
        SummaryReader::new_with_options(SummaryReaderOptions::default().with_file_size(size));
    while let Some(event) = r.next_event() {
        match event {
            Ok(SummaryReadEvent::ReadRequest(n)) => {
                let read = f.read(r.insert(n))?;
                r.notify_read(read);
            }
            Ok(SummaryReadEvent::SeekRequest(to)) => {
                let pos = f.seek(to)?;
                r.notify_seeked(pos);
            }
            Err(_) => return Ok((size, None)),
        }
    }
    Ok((size, r.finish()))
}

/// `FROM=TO` robot remappings.
/// `--remap`s: robot ports (`6665=7000`, as key prefixes) and ROS 2 topics
/// (`/scan=robot/6665/laser/0`, whole names).
#[derive(Default)]
struct Remaps {
    ports: Vec<(String, String)>,
    topics: HashMap<String, String>,
}

fn remaps(list: &[String]) -> anyhow::Result<Remaps> {
    let mut r = Remaps::default();
    for arg in list {
        let (from, to) = arg.split_once('=').with_context(|| {
            format!("--remap {arg}: expected FROM=TO, e.g. 6665=7000 or /scan=robot/6665/laser/0")
        })?;
        if from.starts_with('/') {
            if to != keys::SIM_CLOCK && keys::parse_data(to).is_err() {
                anyhow::bail!(
                    "--remap {arg}: `{to}` is not a device's key (robot/6665/laser/0) or sim/clock"
                );
            }
            r.topics.insert(from.to_owned(), to.to_owned());
            continue;
        }
        let from: u32 = from.parse().with_context(|| {
            format!("--remap {arg}: `{from}` is not a robot port or a ROS 2 topic")
        })?;
        let to: u32 = to
            .parse()
            .with_context(|| format!("--remap {arg}: `{to}` is not a robot port"))?;
        r.ports
            .push((keys::robot_prefix(from), keys::robot_prefix(to)));
    }
    Ok(r)
}

fn remap(key: &str, remaps: &Remaps) -> String {
    for (from, to) in &remaps.ports {
        if let Some(rest) = key.strip_prefix(from.as_str()) {
            return format!("{to}{rest}");
        }
    }
    key.to_owned()
}

/// The key a ROS 2 topic plays on: its `--remap`, or the device its name
/// names (`/robot_6665/laser_0`), then the port remaps.
fn ros2_key(topic: &str, remaps: &Remaps) -> Option<String> {
    let key = match remaps.topics.get(topic) {
        Some(k) => k.clone(),
        None => troupe_ros2::back::key_of_topic(topic)?,
    };
    Some(remap(&key, remaps))
}

/// `troupe play`.
pub fn play(a: PlayArgs, z: &ZenohArgs) -> anyhow::Result<()> {
    ensure_mcap(&a.file)?;
    if !(a.rate.is_finite() && a.rate >= 0.0) {
        anyhow::bail!(
            "--rate {}: expected 0 (as fast as possible) or more",
            a.rate
        );
    }
    let remaps = remaps(&a.remap)?;
    let only = a
        .only
        .iter()
        .map(|k| {
            troupe_node::zenoh::key_expr::OwnedKeyExpr::try_from(k.as_str())
                .map_err(|e| anyhow::anyhow!("--only {k}: {e}"))
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let wanted = |topic: &str| {
        only.is_empty()
            || troupe_node::zenoh::key_expr::keyexpr::new(topic)
                .is_ok_and(|t| only.iter().any(|o| o.intersects(t)))
    };
    let name = a.file.display().to_string();
    let session = z.open(Mode::Client)?;
    // The devices the recording saw live are live again while it plays.
    let mut live = Vec::new();
    let mut publishers = HashMap::new();
    let mut first: Option<u64> = None;
    // A ROS 2 topic that names no device, with its messages.
    let mut unkeyed: BTreeMap<String, u64> = BTreeMap::new();
    each_message(&a.file, |m| {
        first = Some(first.map_or(m.log_time, |f: u64| f.min(m.log_time)));
        let device = m.topic.rsplit_once("/driver/").map_or("", |(d, _)| d);
        if m.encoding == LIVELINESS && m.data.first() == Some(&1) && wanted(device) {
            let key = remap(m.topic, &remaps);
            if !live.contains(&key) {
                live.push(key);
            }
        }
        // A ROS 2 recording has no liveliness: its devices are live as
        // the player's.
        if m.encoding == ros2::CDR {
            match ros2_key(m.topic, &remaps) {
                Some(key) if key != keys::SIM_CLOCK && wanted(&key) => {
                    let token = keys::token_at(&key, "play");
                    if !live.contains(&token) {
                        live.push(token);
                    }
                }
                Some(_) => {}
                None => *unkeyed.entry(m.topic.to_owned()).or_default() += 1,
            }
        }
        Ok(true)
    })?;
    if !unkeyed.is_empty() {
        let topics: Vec<String> = unkeyed.iter().map(|(t, n)| format!("{t} ({n})")).collect();
        tracing::warn!(
            "{name}: {} ROS 2 topics name no Troupe device and are left out: {}; \
             give each a key, e.g. --remap {}=robot/6665/laser/0",
            unkeyed.len(),
            topics.join(", "),
            unkeyed.keys().next().map_or("/scan", String::as_str)
        );
    }
    // What a ROS 2 message could not become, said once per topic at the end.
    let mut refused: BTreeMap<String, (u64, String)> = BTreeMap::new();
    let first = first.with_context(|| format!("{name} holds no message"))?;
    let tokens: Vec<_> = live
        .iter()
        .filter_map(|k| session.liveliness().declare_token(k.as_str()).wait().ok())
        .collect();
    let (from, to) = (
        first + troupe_ros2::stamp_ns(a.start),
        a.end.map_or(u64::MAX, |e| first + troupe_ros2::stamp_ns(e)),
    );
    let stop_rx = troupe_node::process::stop_receiver().context("catching Ctrl-C and SIGTERM")?;
    let started = Instant::now();
    let (mut count, mut bytes) = (0u64, 0u64);
    let mut stopped = false;
    while !stopped {
        let pass = Instant::now();
        each_message(&a.file, |m| {
            if m.log_time < from || m.log_time > to {
                return Ok(true);
            }
            let ros2_sample;
            let (key, data) = match m.encoding {
                ENCODING if wanted(m.topic) => (remap(m.topic, &remaps), m.data),
                ros2::CDR => {
                    let Some(key) = ros2_key(m.topic, &remaps).filter(|k| wanted(k)) else {
                        return Ok(true);
                    };
                    let sample = troupe_ros2::Type::from_name(m.schema)
                        .with_context(|| format!("{} is not a ROS 2 type Troupe reads", m.schema))
                        .and_then(|ty| Ok(troupe_ros2::back::to_sample(ty, &key, m.data)?));
                    match sample {
                        Ok(s) => ros2_sample = s,
                        Err(e) => {
                            let r = refused.entry(m.topic.to_owned()).or_default();
                            r.0 += 1;
                            r.1 = format!("{e:#}");
                            return Ok(true);
                        }
                    }
                    (key, ros2_sample.as_slice())
                }
                _ => return Ok(true),
            };
            let wait = if a.rate > 0.0 {
                let due = pass + Duration::from_secs_f64((m.log_time - from) as f64 / 1e9 / a.rate);
                due.saturating_duration_since(Instant::now())
            } else {
                Duration::ZERO
            };
            if stop_rx.recv_timeout(wait).is_ok() {
                stopped = true;
                return Ok(false);
            }
            if !publishers.contains_key(&key) {
                // Blocking, not dropping, when a subscriber lags: a
                // replay delivers every message, at worst late.
                let p = session
                    .declare_publisher(key.clone())
                    .congestion_control(troupe_node::zenoh::qos::CongestionControl::Block)
                    .wait()
                    .map_err(|e| anyhow::anyhow!("publishing on {key}: {e}"))?;
                publishers.insert(key.clone(), p);
            }
            if let Some(p) = publishers.get(&key) {
                p.put(data.to_vec())
                    .wait()
                    .map_err(|e| anyhow::anyhow!("publishing on {key}: {e}"))?;
            }
            count += 1;
            bytes += data.len() as u64;
            Ok(true)
        })?;
        if !a.repeat {
            break;
        }
    }
    drop(tokens);
    for (topic, (n, why)) in &refused {
        tracing::warn!("{name}: {n} messages on {topic} left out: {why}");
    }
    let secs = started.elapsed().as_secs_f64().max(1e-9);
    writeln!(
        std::io::stdout().lock(),
        "played {count} messages ({:.1} MB) in {secs:.2} s: {:.0} messages/s, {:.1} MB/s",
        bytes as f64 / 1e6,
        count as f64 / secs,
        bytes as f64 / 1e6 / secs
    )?;
    Ok(())
}

/// `troupe log`.
pub fn log(cmd: LogCmd) -> anyhow::Result<()> {
    match cmd {
        LogCmd::Info { file } => {
            ensure_mcap(&file)?;
            info(&file)
        }
        LogCmd::Export {
            file,
            format,
            output,
            rosbag2,
        } => {
            ensure_mcap(&file)?;
            if rosbag2 {
                let dir = output.context("--rosbag2 writes a directory: name it with -o DIR")?;
                anyhow::ensure!(
                    matches!(format, Format::Json | Format::Ros2),
                    "--rosbag2 is a directory of ROS 2 messages: not --format {}",
                    format!("{format:?}").to_lowercase()
                );
                return export_as(&file, &dir, Converter::rosbag2(), true);
            }
            match (format, output) {
                (Format::Ros2, Some(out)) => export_as(&file, &out, Converter::ros2(), false),
                (Format::Foxglove, Some(out)) => {
                    export_as(&file, &out, Converter::foxglove(), false)
                }
                (Format::Ros2 | Format::Foxglove, None) => anyhow::bail!(
                    "--format {} writes MCAP, not text: name the file with -o OUT.mcap",
                    format!("{format:?}").to_lowercase()
                ),
                (_, Some(out)) => {
                    let f = std::fs::File::create(&out)
                        .with_context(|| format!("creating {}", out.display()))?;
                    export(&file, format, f)
                }
                (_, None) => export(&file, format, std::io::stdout().lock()),
            }
        }
    }
}

/// Makes the rosbag2 directory `dir` (which must not hold anything yet:
/// `ros2 bag record` refuses one that exists) and says where its MCAP
/// file goes: `dir/NAME_0.mcap` (split: `dir/NAME.mcap`, which the files
/// are numbered after).
fn rosbag2_base(dir: &Path, split: bool) -> anyhow::Result<PathBuf> {
    if let Ok(mut entries) = std::fs::read_dir(dir) {
        anyhow::ensure!(
            entries.next().is_none(),
            "{} exists and is not empty: a rosbag2 directory is written whole, into a new one",
            dir.display()
        );
    }
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let name = dir
        .file_name()
        .map_or_else(|| "bag".into(), |n| n.to_string_lossy().into_owned());
    Ok(dir.join(if split {
        format!("{name}.mcap")
    } else {
        format!("{name}_0.mcap")
    }))
}

/// Writes `dir/metadata.yaml` for what `w` wrote into `files`.
fn write_metadata(dir: &Path, files: &Files, w: &Converter) -> anyhow::Result<()> {
    if let Some(yaml) = w.metadata(files.written()) {
        let path = dir.join("metadata.yaml");
        std::fs::write(&path, yaml).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

/// The first bytes of the file at `path` (64 at most).
fn head(path: &Path) -> std::io::Result<Vec<u8>> {
    use std::io::Read as _;
    let mut head = Vec::with_capacity(64);
    std::fs::File::open(path)?.take(64).read_to_end(&mut head)?;
    Ok(head)
}

/// Whether the file at `path` is an MCAP file, by its first bytes.
///
/// # Errors
///
/// The file cannot be read.
pub fn is_mcap(path: &Path) -> std::io::Result<bool> {
    Ok(head(path)?.starts_with(mcap::MAGIC))
}

/// Fails, saying what the file is instead, unless `path` is an MCAP file.
fn ensure_mcap(path: &Path) -> anyhow::Result<()> {
    let head = head(path).with_context(|| format!("opening {}", path.display()))?;
    if head.starts_with(mcap::MAGIC) {
        return Ok(());
    }
    if head.starts_with(b"## Player") {
        anyhow::bail!(
            "{} is a Player text log, not an MCAP recording: the readlog driver replays it \
             (`driver ( name \"readlog\" filename \"{}\" … )`), and `troupe map build` reads it",
            path.display(),
            path.file_name()
                .map_or_else(String::new, |f| f.to_string_lossy().into_owned())
        );
    }
    anyhow::bail!(
        "{} is not an MCAP recording (MCAP files begin with \\x89MCAP0; `troupe record` writes them)",
        path.display()
    )
}

fn info(path: &Path) -> anyhow::Result<()> {
    let name = path.display().to_string();
    let mut out = std::io::stdout().lock();
    // The summary at the end says it all without reading the messages.
    let (size, summary) = summary(path)?;
    let (counts, channels, start, end, total, stamps) = match summary
        .as_ref()
        .and_then(|s| s.stats.as_ref().map(|st| (s, st)))
    {
        Some((s, st)) => {
            let channels: BTreeMap<u16, (String, String, String)> = s
                .channels
                .iter()
                .map(|(id, c)| {
                    let schema = c
                        .schema
                        .as_ref()
                        .map(|s| s.name.clone())
                        .unwrap_or_default();
                    (*id, (c.topic.clone(), schema, c.message_encoding.clone()))
                })
                .collect();
            let stamps = stamp_span(path, s, st.message_start_time, st.message_end_time)?;
            (
                st.channel_message_counts.clone(),
                channels,
                st.message_start_time,
                st.message_end_time,
                st.message_count,
                stamps,
            )
        }
        None => {
            writeln!(
                out,
                "{name}: no summary (a recording that did not finish): reading every message"
            )?;
            // Channels named by key and schema, numbered as they come.
            let mut ids: HashMap<(String, String), u16> = HashMap::new();
            let mut counts = BTreeMap::new();
            let mut channels = BTreeMap::new();
            let (mut start, mut end, mut total) = (u64::MAX, 0, 0);
            let mut stamps: Option<(u64, u64)> = None;
            each_message(path, |m| {
                if m.encoding == ENCODING {
                    let t = m.publish_time;
                    stamps = Some(stamps.map_or((t, t), |(a, b)| (a.min(t), b.max(t))));
                }
                let next = u16::try_from(ids.len()).unwrap_or(u16::MAX);
                let id = *ids
                    .entry((m.topic.to_owned(), m.schema.to_owned()))
                    .or_insert(next);
                *counts.entry(id).or_insert(0u64) += 1;
                channels.entry(id).or_insert_with(|| {
                    (
                        m.topic.to_owned(),
                        m.schema.to_owned(),
                        m.encoding.to_owned(),
                    )
                });
                start = start.min(m.log_time);
                end = end.max(m.log_time);
                total += 1;
                Ok(true)
            })?;
            (counts, channels, start.min(end), end, total, stamps)
        }
    };
    let secs = end.saturating_sub(start) as f64 / 1e9;
    writeln!(out, "file:      {name}")?;
    writeln!(out, "size:      {:.1} MB", size as f64 / 1e6)?;
    writeln!(out, "duration:  {secs:.3} s")?;
    if let Some((first, last)) = stamps {
        let s = |ns: u64| ns as f64 / 1e9;
        writeln!(
            out,
            "stamps:    {:.3} s, {:.3} to {:.3} (the drivers' clock: simulated time under a simulator)",
            s(last.saturating_sub(first)),
            s(first),
            s(last)
        )?;
    }
    writeln!(out, "messages:  {total}")?;
    let mut topics: Vec<(&String, &String, &String, u64)> = channels
        .iter()
        .map(|(id, (t, s, e))| (t, s, e, counts.get(id).copied().unwrap_or(0)))
        .collect();
    topics.sort();
    writeln!(out, "channels:  {}", topics.len())?;
    for (topic, schema, encoding, n) in topics {
        if encoding == LIVELINESS {
            writeln!(out, "  {topic:<48} liveliness, {n} events")?;
        } else {
            let hz = if secs > 0.0 { n as f64 / secs } else { 0.0 };
            writeln!(
                out,
                "  {topic:<48} {schema:<24} {n:>8} msgs  {hz:>8.1} msgs/s"
            )?;
        }
    }
    // What the rate counts: rangertolaser's scan is two messages (ranges,
    // then intensities, as Player's), so its rate reads twice `hz`'s.
    writeln!(
        out,
        "(msgs/s counts every message; `troupe hz` counts a device's updates, one per stamp and kind)"
    )?;
    Ok(())
}

/// The first and last stamps (ns) of a recording's samples, from its
/// first and last [`EDGE`] of log time, read through the summary's chunk
/// indexes: the middle of a large file is never read.
fn stamp_span(
    path: &Path,
    summary: &mcap::Summary,
    start: u64,
    end: u64,
) -> anyhow::Result<Option<(u64, u64)>> {
    use mcap::sans_io::indexed_reader::{IndexedReadEvent, IndexedReader, IndexedReaderOptions};
    use std::io::{Read as _, Seek as _};
    let samples: std::collections::HashSet<u16> = summary
        .channels
        .iter()
        .filter(|(_, c)| c.message_encoding == ENCODING)
        .map(|(id, _)| *id)
        .collect();
    let name = path.display().to_string();
    let mut f = std::fs::File::open(path).with_context(|| format!("opening {name}"))?;
    let mut buf = Vec::new();
    let mut edge = |options: IndexedReaderOptions, pick: fn(u64, u64) -> u64| {
        let mut r = IndexedReader::new_with_options(summary, options)
            .with_context(|| format!("{name}: its chunk indexes"))?;
        let mut found: Option<u64> = None;
        while let Some(event) = r.next_event() {
            match event.with_context(|| format!("reading {name}"))? {
                IndexedReadEvent::ReadChunkRequest { offset, length } => {
                    f.seek(std::io::SeekFrom::Start(offset))?;
                    buf.resize(length, 0);
                    f.read_exact(&mut buf)?;
                    r.insert_chunk_record_data(offset, &buf)
                        .with_context(|| format!("reading {name}"))?;
                }
                IndexedReadEvent::Message { header, .. } => {
                    if samples.contains(&header.channel_id) {
                        let t = header.publish_time;
                        found = Some(found.map_or(t, |s| pick(s, t)));
                    }
                }
            }
        }
        anyhow::Ok(found)
    };
    let first = edge(
        IndexedReaderOptions::new().log_time_before(start.saturating_add(EDGE)),
        u64::min,
    )?;
    let last = edge(
        IndexedReaderOptions::new().log_time_on_or_after(end.saturating_sub(EDGE)),
        u64::max,
    )?;
    Ok(first.zip(last))
}

/// How much log time at each end of a recording [`stamp_span`] reads, ns:
/// a sample stamped before the first or after the last sample received
/// within it is not seen.
const EDGE: u64 = 2_000_000_000;

fn export(path: &Path, format: Format, out: impl std::io::Write) -> anyhow::Result<()> {
    let mut out = std::io::BufWriter::new(out);
    if format == Format::Player {
        out.write_all(troupe_log::text::header().as_bytes())?;
    }
    let mut skipped = 0u64;
    each_message(path, |m| {
        if m.encoding != ENCODING {
            return Ok(true);
        }
        let Ok(s) = decode_any(m.data) else {
            skipped += 1;
            return Ok(true);
        };
        match format {
            Format::Json => {
                let line = serde_json::json!({
                    "time": m.log_time as f64 / 1e9,
                    "key": m.topic,
                    "stamp": s.stamp,
                    "msg": s.msg,
                });
                writeln!(out, "{line}")?;
            }
            Format::Ros2 | Format::Foxglove => unreachable!("MCAP is exported by export_as"),
            Format::Player => {
                let line = keys::parse_data(m.topic).ok().and_then(|d| {
                    troupe_log::text::line(s.stamp, d.robot, d.interface, d.index, &s.msg)
                });
                match line {
                    Some(l) => out.write_all(l.as_bytes())?,
                    None => skipped += 1,
                }
            }
        }
        Ok(true)
    })?;
    out.flush()?;
    if skipped > 0 {
        eprintln!(
            "troupe log export: {skipped} messages have no {format:?} form and were left out"
        );
    }
    Ok(())
}

/// `troupe log export --format ros2|foxglove`: the recording's samples as
/// ROS 2 or Foxglove messages in `out`, and a summary of what went where on
/// standard error.
fn export_as(path: &Path, out: &Path, mut w: Converter, bag: bool) -> anyhow::Result<()> {
    let base = if bag {
        rosbag2_base(out, false)?
    } else {
        out.to_owned()
    };
    let mut files = Files::new(base, false, Compress::None).with_profile(w.profile());
    files.open(0)?;
    let (mut samples, mut events) = (0u64, 0u64);
    each_message(path, |m| {
        if m.encoding == ENCODING {
            samples += 1;
            w.write(&mut files, m.topic, m.data, m.log_time)?;
        } else {
            events += 1;
        }
        Ok(true)
    })?;
    files.close()?;
    if bag {
        write_metadata(out, &files, &w)?;
    }
    eprint!(
        "troupe log export: {samples} samples of {} as {} messages in {}{}:\n{}",
        path.display(),
        w.name(),
        out.display(),
        match w.json_count() {
            0 => String::new(),
            n => format!(" ({n} with no {} form, as JSON)", w.name()),
        },
        w.summary()
    );
    if events > 0 {
        eprintln!(
            "  ({events} liveliness events: {} has no form for them, left out)",
            w.name()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_that_is_not_mcap_is_refused_saying_what_it_is() {
        let dir = std::env::temp_dir().join(format!("troupe-record-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let log = dir.join("run.log");
        std::fs::write(
            &log,
            "## Player version 3.1.1-dev \n## File version 0.3.0 \n",
        )
        .unwrap();
        let e = format!("{:#}", log_info(&log));
        assert!(
            e.contains("run.log is a Player text log, not an MCAP recording"),
            "{e}"
        );
        assert!(e.contains("readlog"), "{e}");
        let junk = dir.join("junk.bin");
        std::fs::write(&junk, b"hello").unwrap();
        let e = format!("{:#}", log_info(&junk));
        assert!(e.contains("junk.bin is not an MCAP recording"), "{e}");
        let e = format!("{:#}", log_info(&dir.join("absent.mcap")));
        assert!(e.contains("opening") && e.contains("absent.mcap"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    fn log_info(path: &Path) -> anyhow::Error {
        log(LogCmd::Info {
            file: path.to_owned(),
        })
        .unwrap_err()
    }
}
