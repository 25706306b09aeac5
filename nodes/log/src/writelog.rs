//! Player's `writelog`: writes the data of its required devices to a
//! Player text log.
//!
//! ```text
//! driver ( name "writelog" requires ["laser:0" "position2d:0"] provides ["log:0"]
//!          filename "run.log" alwayson 1 )
//! ```
//!
//! | | |
//! |---|---|
//! | requires | the devices to log, any interface the format has a layout for |
//! | provides | one `log` (start/stop, state, file name) |
//! | options | `filename`, or `log_directory` + `basename` (`writelog_`) + `timestamp` (1) + `extension` (`.log`); `timestamp_directory` (0), `autorecord` (1), `write_particles` (0), `camera_log_images` (1), `camera_save_images` (0) |
//!
//! # Behavior
//!
//! - The file opens at start with Player's header, then the geometry of
//!   each laser, ranger (and its configuration), position2d, sonar, bumper
//!   and ir, asked for in `requires` order; data that arrives before every
//!   geometry is in waits, so geometries come first as in Player's logs.
//! - Each data sample is one line, stamped with the sample's stamp
//!   (simulation time under a simulator), written and flushed at once.
//!   A message the format has no layout for is skipped, said once per kind
//!   with a count at the end.
//! - `log` requests: `set_write_state` starts and stops, `get_state` says
//!   which, `set_filename` closes the file and opens another (refused while
//!   writing). With `write_particles 1`, each localize estimate is followed
//!   by the particle set.
//! - A camera image is written in the line as hex (`camera_log_images 0`:
//!   its sizes only, as Player wrote them); `camera_save_images 1` also
//!   writes each image beside the log as Player named them,
//!   `<log's stem>_camera_<index>_<frame>.pnm` (raw 8-bit grey or RGB) or
//!   `.jpg` (JPEG).
//! - A failed write (a full disk) is an error at once naming the file; the
//!   lines before it stay in the file, and writing stops until a new
//!   `set_filename`.
//! - Timestamps in file names are UTC (Player used local time).

use std::collections::{BTreeMap, HashMap};

use std::io::Write as _;
use std::path::PathBuf;

use serde::Deserialize;
use troupe_msgs::{
    bumper, camera, decode_any, fiducial, ir, laser, localize, log, position2d, ranger, sonar,
    AnyMsg, Device, Interface, Stamped,
};
use troupe_node::{
    Ctx, Driver, Event, NodeError, RequestError, RequestId, Result, Sample, Section, Switch,
};

use crate::text;

/// Options, by Player's names.
#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub struct Options {
    /// The file (relative: under `log_directory`); default
    /// `basename` + timestamp + `extension`.
    pub filename: Option<String>,
    /// Where the file goes (created); default the working directory.
    pub log_directory: Option<PathBuf>,
    /// Add a timestamp to `log_directory`.
    pub timestamp_directory: Option<Switch>,
    /// Default `writelog_`.
    pub basename: Option<String>,
    /// Add a timestamp to the default file name (default on).
    pub timestamp: Option<Switch>,
    /// Default `.log`.
    pub extension: Option<String>,
    /// Write from the start (default on).
    pub autorecord: Option<Switch>,
    /// After each localize estimate, ask for and log the particles.
    pub write_particles: Option<Switch>,
    /// Write each camera image into its line, as hex (default on).
    pub camera_log_images: Option<Switch>,
    /// Also write each camera image to a file of its own (default off).
    pub camera_save_images: Option<Switch>,
}

/// The writelog driver.
pub struct WriteLog {
    inputs: Vec<Device>,
    path: PathBuf,
    directory: PathBuf,
    file: Option<std::fs::File>,
    enabled: bool,
    particles: bool,
    /// Camera images into the log's lines; into files of their own, with
    /// each camera's next frame number.
    log_images: bool,
    save_images: Option<HashMap<Device, u32>>,
    /// The geometry requests in `requires` order, each with its answer's
    /// line once in (`None` while waiting), and the data lines held until
    /// all are in.
    asked: Vec<(RequestId, Device, Option<Option<String>>)>,
    held: Vec<String>,
    particle_requests: HashMap<RequestId, Device>,
    /// Lines written; kinds of message skipped, with counts.
    lines: u64,
    skipped: BTreeMap<Device, BTreeMap<String, u64>>,
}

fn timestamp() -> String {
    let now = time::OffsetDateTime::now_utc();
    format!(
        "{:04}_{:02}_{:02}_{:02}_{:02}_{:02}",
        now.year(),
        u8::from(now.month()),
        now.day(),
        now.hour(),
        now.minute(),
        now.second()
    )
}

impl Driver for WriteLog {
    const NAME: &'static str = "writelog";
    type Options = Options;

    fn new(section: &Section, o: Options) -> Result<Self> {
        let stamp = timestamp();
        let with_stamp = |s: Option<Switch>, default: bool| s.map_or(default, Switch::on);
        let filename = o.filename.clone().unwrap_or_else(|| {
            format!(
                "{}{}{}",
                o.basename.as_deref().unwrap_or("writelog_"),
                if with_stamp(o.timestamp, true) {
                    stamp.as_str()
                } else {
                    ""
                },
                o.extension.as_deref().unwrap_or(".log")
            )
        });
        let mut directory = o.log_directory.clone().unwrap_or_default();
        if with_stamp(o.timestamp_directory, false) {
            let mut d = directory.into_os_string();
            d.push(&stamp);
            directory = d.into();
        }
        if directory.as_os_str().is_empty() {
            directory = ".".into();
        }
        let inputs = section.required_where(|_| true);
        if inputs.is_empty() {
            return Err(NodeError::config(
                Self::NAME,
                "`requires` names no device to log",
            ));
        }
        // Its one device, which every request is for.
        section.provided_one(Interface::Log, None)?;
        Ok(WriteLog {
            inputs,
            path: directory.join(filename),
            directory,
            file: None,
            enabled: o.autorecord.is_none_or(Switch::on),
            particles: o.write_particles.is_some_and(Switch::on),
            log_images: o.camera_log_images.is_none_or(Switch::on),
            save_images: o
                .camera_save_images
                .is_some_and(Switch::on)
                .then(HashMap::new),
            asked: Vec::new(),
            held: Vec::new(),
            particle_requests: HashMap::new(),
            lines: 0,
            skipped: BTreeMap::new(),
        })
    }

    fn setup(&mut self, ctx: &mut Ctx) -> Result<()> {
        for d in self.inputs.clone() {
            ctx.subscribe(&d)?;
        }
        self.open(ctx)
    }

    fn on_event(&mut self, ctx: &mut Ctx, event: Event) -> Result<()> {
        match event {
            Event::Data(s) => self.data(ctx, &s),
            Event::Reply(r) => {
                if let Some(dev) = self.particle_requests.remove(&r.id) {
                    match answer(&r) {
                        Ok(m) => self.write_msg(
                            dev,
                            <localize::Particles as troupe_msgs::Message>::SCHEMA,
                            m.stamp,
                            &m.msg,
                        )?,
                        Err(e) => tracing::warn!("unable to get {dev}'s particles ({e})"),
                    }
                    return Ok(());
                }
                let Some(slot) = self.asked.iter_mut().find(|a| a.0 == r.id) else {
                    return Ok(());
                };
                let dev = slot.1;
                slot.2 = Some(match answer(&r) {
                    Ok(m) => text::line(m.stamp, dev.robot, dev.interface, dev.index, &m.msg),
                    Err(e) => {
                        tracing::warn!(
                            "unable to get the geometry of {dev} ({e}); logging without it"
                        );
                        None
                    }
                });
                if self.asked.iter().all(|a| a.2.is_some()) {
                    // In `requires` order, as Player asked one by one; then the data.
                    let lines: Vec<String> = std::mem::take(&mut self.asked)
                        .into_iter()
                        .filter_map(|a| a.2.flatten())
                        .chain(std::mem::take(&mut self.held))
                        .collect();
                    for line in lines {
                        self.write(&line)?;
                    }
                }
                Ok(())
            }
            Event::Request(r) if r.is::<log::SetWriteState>() => {
                let on = r.decode::<log::SetWriteState>()?.state;
                tracing::info!(
                    "{} logging to {}",
                    if on { "start" } else { "stop" },
                    self.path.display()
                );
                self.enabled = on;
                r.reply(&troupe_msgs::common::Ack);
                Ok(())
            }
            Event::Request(r) if r.is::<log::GetState>() => {
                r.reply(&log::State {
                    kind: log::TYPE_WRITE,
                    state: self.enabled,
                });
                Ok(())
            }
            Event::Request(r) if r.is::<log::SetFilename>() => {
                if self.enabled {
                    r.nack(
                        "tried to switch file names while logging: stop first (set_write_state 0)",
                    );
                    return Ok(());
                }
                let name = r.decode::<log::SetFilename>()?.filename;
                self.close();
                let p = PathBuf::from(&name);
                self.path = if p.is_absolute() {
                    p
                } else {
                    self.directory.join(p)
                };
                match self.open(ctx) {
                    Ok(()) => r.reply(&troupe_msgs::common::Ack),
                    Err(e) => r.nack(e.to_string()),
                }
                Ok(())
            }
            Event::Request(r) => {
                r.unhandled(Self::NAME);
                Ok(())
            }
            Event::Command(c) => {
                tracing::debug!("log takes no commands; ignored `{}`", c.key);
                Ok(())
            }
            Event::Tick | Event::Wake => Ok(()),
        }
    }

    fn shutdown(&mut self, _: &mut Ctx) -> Result<()> {
        self.close();
        Ok(())
    }
}

impl WriteLog {
    /// Opens the file, writes the header and asks for the geometries.
    fn open(&mut self, ctx: &mut Ctx) -> Result<()> {
        let fail = |what: &str, e: std::io::Error| {
            NodeError::config(Self::NAME, format!("{what} {}: {e}", self.path.display()))
        };
        if let Some(dir) = self.path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| fail("cannot create the directory of", e))?;
        }
        let mut f = std::fs::File::create(&self.path).map_err(|e| fail("cannot open", e))?;
        f.write_all(text::header().as_bytes())
            .map_err(|e| fail("cannot write", e))?;
        self.file = Some(f);
        tracing::info!(
            "logging {} device(s) to {}",
            self.inputs.len(),
            self.path.display()
        );
        self.asked.clear();
        for d in self.inputs.clone() {
            let mut ask = |id: Result<RequestId>| -> Result<()> {
                self.asked.push((id?, d, None));
                Ok(())
            };
            match d.interface {
                Interface::Laser => ask(ctx.request(&d, &laser::GetGeom))?,
                Interface::Ranger => {
                    ask(ctx.request(&d, &ranger::GetGeom))?;
                    ask(ctx.request(&d, &ranger::GetConfig))?;
                }
                Interface::Position2d => ask(ctx.request(&d, &position2d::GetGeom))?,
                Interface::Sonar => ask(ctx.request(&d, &sonar::GetGeom))?,
                Interface::Bumper => ask(ctx.request(&d, &bumper::GetGeom))?,
                Interface::Ir => ask(ctx.request(&d, &ir::GetGeom))?,
                Interface::Fiducial => ask(ctx.request(&d, &fiducial::GetGeom))?,
                _ => {}
            }
        }
        Ok(())
    }

    fn close(&mut self) {
        if let Some(mut f) = self.file.take() {
            let _ = f.flush();
            tracing::info!("closed {} after {} lines", self.path.display(), self.lines);
        }
        for (dev, counts) in std::mem::take(&mut self.skipped) {
            for (schema, n) in counts {
                tracing::info!(
                    "skipped {n} message(s) of {schema} from {dev}: Player's log format has no layout for them"
                );
            }
        }
    }

    fn data(&mut self, ctx: &mut Ctx, s: &Sample) -> Result<()> {
        if !self.enabled || self.file.is_none() {
            return Ok(());
        }
        let m = match decode_any(&s.payload().to_bytes()) {
            Ok(m) => m,
            Err(e) => {
                return Err(NodeError::Decode {
                    key: s.key.clone(),
                    source: e,
                })
            }
        };
        let dev = s.device;
        if self.particles && matches!(m.msg, AnyMsg::LocalizeHypoths(_)) {
            let id = ctx.request(&dev, &localize::GetParticles)?;
            self.particle_requests.insert(id, dev);
        }
        self.write_msg(dev, &s.schema(), m.stamp, &m.msg)
    }

    /// Writes `msg` (of schema tag `schema`) from `dev`, or holds it until
    /// the geometries are in, or counts it when the format has no layout.
    fn write_msg(&mut self, dev: Device, schema: &str, stamp: f64, msg: &AnyMsg) -> Result<()> {
        if let AnyMsg::CameraData(image) = msg {
            self.save_image(dev, image);
        }
        let Some(mut line) = text::line(stamp, dev.robot, dev.interface, dev.index, msg) else {
            let counts = self.skipped.entry(dev).or_default();
            match counts.get_mut(schema) {
                Some(n) => *n += 1,
                None => {
                    tracing::warn!("not logging {schema} from {dev}: Player's log format has no layout for it (said once; counted)");
                    counts.insert(schema.to_owned(), 1);
                }
            }
            return Ok(());
        };
        if matches!(msg, AnyMsg::CameraData(_)) && !self.log_images {
            // The sizes only: the line ends after the image's count, as
            // Player's did.
            if let Some(cut) = line.rfind(' ') {
                line.truncate(cut + 1);
                line.push('\n');
            }
        }
        if self.asked.is_empty() {
            self.write(&line)
        } else {
            self.held.push(line);
            Ok(())
        }
    }

    /// With `camera_save_images`, writes `image` from camera `dev` to its
    /// own file beside the log, named as Player named them; a failure is
    /// said and the log goes on.
    fn save_image(&mut self, dev: Device, image: &camera::Data) {
        let Some(frames) = self.save_images.as_mut() else {
            return;
        };
        let frame = frames.entry(dev).or_insert(0);
        let header = match (image.compression, image.format) {
            (camera::COMPRESS_RAW, camera::FORMAT_RGB888) => Some("P6"),
            (camera::COMPRESS_RAW, camera::FORMAT_MONO8) => Some("P5"),
            (camera::COMPRESS_JPEG, _) => None,
            _ => {
                tracing::warn!(
                    "camera {dev}: not saving an image of format {} compression {} (Player saved raw 8-bit grey and RGB, and JPEG)",
                    image.format,
                    image.compression
                );
                return;
            }
        };
        let stem = self
            .path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let ext = if header.is_some() { "pnm" } else { "jpg" };
        let file = self
            .path
            .with_file_name(format!("{stem}_camera_{:02}_{frame:06}.{ext}", dev.index));
        *frame += 1;
        let mut bytes = header
            .map(|h| format!("{h}\n{} {}\n255\n", image.width, image.height).into_bytes())
            .unwrap_or_default();
        bytes.extend_from_slice(&image.image);
        if let Err(e) = std::fs::write(&file, bytes) {
            tracing::error!("cannot write camera image {}: {e}", file.display());
        }
    }

    fn write(&mut self, line: &str) -> Result<()> {
        let Some(f) = self.file.as_mut() else {
            return Ok(());
        };
        // One write per line, as Player flushed each: what is written stays
        // readable whatever happens next.
        if let Err(e) = f.write_all(line.as_bytes()) {
            self.file = None;
            tracing::error!(
                "cannot write {} after {} lines: {e}; logging stopped (the file so far is intact; set_filename opens another)",
                self.path.display(),
                self.lines
            );
            return Ok(());
        }
        self.lines += 1;
        Ok(())
    }
}

/// A reply's message, or why there is none.
fn answer(r: &troupe_node::Reply) -> std::result::Result<Stamped<AnyMsg>, RequestError> {
    match &r.result {
        Ok(s) => decode_any(&s.payload().to_bytes()).map_err(RequestError::Decode),
        Err(e) => Err(e.clone()),
    }
}
