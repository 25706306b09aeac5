//! The world as Stage loads it: typed models from a parsed world file.
//!
//! Units in the file are metres and degrees unless the file sets
//! `unit_length`/`unit_angle`; everything here is metres and radians. Block
//! and bitmap bodies are stretched so their bounding box is exactly the
//! model's `size`, centred on the model, as Stage's `CalcSize` does.

use std::cell::{Cell, RefCell};
use std::collections::{BTreeMap, HashMap};
use std::f64::consts::PI;
use std::path::Path;

use troupe_geom::bitmap::Bitmap;
use troupe_geom::{bounds, Pose};
use troupe_msgs::Color;

use crate::colors;
use crate::worldfile::{self, Entity, Pos, Prop, Val, WorldError};

/// Model types Stage 4 knows (plus Stage 3's `laser`, read as a ranger).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A plain model (walls, floorplans, objects).
    Model,
    /// A mobile base.
    Position,
    /// Range sensors (`sensor` children; Stage 3 `laser`).
    Ranger,
    /// A colour-blob camera.
    Blobfinder,
    /// A fiducial detector.
    Fiducial,
    /// A gripper.
    Gripper,
    /// Contact bumpers.
    Bumper,
    /// A camera (drawn by rays: see `sim::camera`).
    Camera,
    /// Other Stage 4 types, loaded as plain models.
    Other,
}

/// How a position model moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Drive {
    /// Differential: forward speed and turn rate.
    Diff,
    /// Holonomic: x, y and turn.
    Omni,
    /// Car-like: speed and steering angle.
    Car,
}

/// Where a position model's reported pose comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Localization {
    /// The true pose, relative to `localization_origin`.
    Gps,
    /// Integrated odometry with `odom_error`.
    Odom,
}

/// A position model's settings.
#[derive(Debug, Clone, PartialEq)]
pub struct PositionCfg {
    /// Drive type.
    pub drive: Drive,
    /// `[xmin xmax ymin ymax zmin zmax amin amax]`, m/s and rad/s.
    pub velocity_bounds: [f64; 8],
    /// Same layout, m/s² and rad/s²: read, but as in Stage they bound
    /// only its acceleration control, which nothing here commands.
    pub acceleration_bounds: [f64; 8],
    /// Reported pose source.
    pub localization: Localization,
    /// Frame of the reported pose (default: the model's pose at load).
    pub localization_origin: Option<Pose>,
    /// Proportional odometry errors (x, y, yaw); `None` when the world
    /// sets none, for Stage's default: drawn per robot (see
    /// `Motion::of`).
    pub odom_error: Option<[f64; 3]>,
    /// Metres, for car drive.
    pub wheelbase: f64,
}

/// One ranger sensor.
#[derive(Debug, Clone, PartialEq)]
pub struct Sensor {
    /// Pose relative to the ranger.
    pub pose: Pose,
    /// Height above the ranger's base.
    pub z: f64,
    /// `[x y z]` metres.
    pub size: [f64; 3],
    /// Metres.
    pub range: (f64, f64),
    /// Radians.
    pub fov: f64,
    /// Beams.
    pub samples: usize,
}

/// A blobfinder's settings (Stage's defaults).
#[derive(Debug, Clone, PartialEq)]
pub struct BlobfinderCfg {
    /// Colours it tracks, in order.
    pub colors: Vec<Color>,
    /// Image width and height, pixels.
    pub image: (u32, u32),
    /// Metres.
    pub range: f64,
    /// Horizontal field of view, radians.
    pub fov: f64,
    /// Pan, radians.
    pub pan: f64,
}

/// A camera's settings (Stage's defaults). Stage reads `fov` and
/// `pantilt` in degrees whatever the world's angle unit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraCfg {
    /// Image width and height, pixels.
    pub resolution: (u32, u32),
    /// Nearest and farthest depth drawn (the view's clip planes), metres.
    pub range: (f64, f64),
    /// Horizontal and vertical field of view, whole angles, radians.
    pub fov: (f64, f64),
    /// Pan (positive turns right) and tilt (positive looks down), radians.
    pub pantilt: (f64, f64),
}

/// A fiducial detector's settings (Stage's defaults).
#[derive(Debug, Clone, PartialEq)]
pub struct FiducialCfg {
    /// Metres.
    pub range_min: f64,
    /// Metres: fiducials are seen up to here…
    pub range_max: f64,
    /// …and identified up to here.
    pub range_max_id: f64,
    /// Radians.
    pub fov: f64,
}

/// A model's part in Stage's energy model (its power pack, what it uses
/// while it runs, what it gives and takes as a charger and a charged).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Energy {
    /// Its own power pack: joules stored and its capacity (`joules`,
    /// `kjoules` and their `*_capacity`); a store below 0 never runs out.
    /// A model without one draws on its nearest ancestor's.
    pub pack: Option<(f64, f64)>,
    /// Watts it uses while it runs (`watts`; a position model's follow
    /// its speed, a ranger's its sensors, as in Stage).
    pub watts: f64,
    /// Watts it gives at most to each pack that touches it (`give_watts`).
    pub give: f64,
    /// Watts it takes at most from a giver it touches (`take_watts`).
    pub take: f64,
    /// Kilograms (`mass`): a position model uses 10 W per kg per m/s.
    pub mass: f64,
    /// Runs with no one to read it (`alwayson`): a charger gives.
    pub always_on: bool,
}

/// A model with everything the simulator needs.
#[derive(Debug, Clone)]
pub struct ModelDef {
    /// Stage's name (`r0`, `r0.ranger:1`…).
    pub name: String,
    /// Type.
    pub kind: Kind,
    /// Parent model.
    pub parent: Option<usize>,
    /// Child models in file order.
    pub children: Vec<usize>,
    /// Pose relative to the parent.
    pub pose: Pose,
    /// Height of the pose above the parent's base.
    pub z: f64,
    /// `[x y z]` metres.
    pub size: [f64; 3],
    /// Offset of the body from the pose.
    pub origin: Pose,
    /// Colour.
    pub color: Color,
    /// Body polygons in the model's frame (origin applied), metres.
    pub blocks: Vec<Vec<(f64, f64)>>,
    /// Each block's base and top above the model's base, metres: a
    /// `block`'s `z` (0 to 1 unless given) scaled as Stage scales it, by
    /// the model's height over the highest block top less the lowest base.
    pub block_z: Vec<(f64, f64)>,
    /// Robots collide with it.
    pub obstacle_return: bool,
    /// Seen by rangers (≥ 0), with this intensity.
    pub ranger_return: f64,
    /// Seen by blobfinders.
    pub blob_return: bool,
    /// Fiducial id (0 = not a fiducial).
    pub fiducial_return: i32,
    /// Can be gripped.
    pub gripper_return: bool,
    /// Children stack on top of it.
    pub stack_children: bool,
    /// Metres per cell of the map a `map` device draws from this model
    /// (Stage's `map_resolution`, 0.1 by default).
    pub map_resolution: f64,
    /// Position settings, for position models.
    pub position: Option<PositionCfg>,
    /// Sensors, for rangers.
    pub sensors: Vec<Sensor>,
    /// Controllers (`ctrl "wander"`).
    pub ctrl: Vec<String>,
    /// Seconds between its updates (Stage's `update_interval`, 100 ms).
    pub update_interval: f64,
    /// Energy: power pack, use, charging.
    pub energy: Energy,
    /// Blobfinder settings, for blobfinders.
    pub blobfinder: Option<BlobfinderCfg>,
    /// Fiducial detector settings, for fiducial models.
    pub fiducial: Option<FiducialCfg>,
    /// Camera settings, for cameras.
    pub camera: Option<CameraCfg>,
    /// Where it was written.
    pub pos: Pos,
}

impl ModelDef {
    /// Its body's lowest base and highest top above its base: those of its
    /// blocks, or 0 and its height when it has none.
    pub fn body_span(&self) -> (f64, f64) {
        if self.block_z.is_empty() {
            return (0.0, self.size[2]);
        }
        self.block_z
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), b| {
                (lo.min(b.0), hi.max(b.1))
            })
    }
}

/// A loaded world.
#[derive(Debug, Clone)]
pub struct World {
    /// Metres per raster cell.
    pub resolution: f64,
    /// Seconds of simulated time per step.
    pub interval_sim: f64,
    /// Simulated seconds after which a headless run stops (0 = never).
    pub quit_time: f64,
    /// Real-time factor (1 = real time; ≤ 0 = as fast as possible).
    pub speedup: f64,
    /// Worker threads the world asks for.
    pub threads: usize,
    /// Start paused.
    pub paused: bool,
    /// The models, parents before children.
    pub models: Vec<ModelDef>,
    /// Every name a model answers to → index.
    pub names: HashMap<String, usize>,
}

/// A block's outline: its corners in order.
type Polygon = Vec<(f64, f64)>;

struct Reader {
    len: f64,
    ang: f64,
    /// Warnings, each with how many models it concerns: a problem of a
    /// `define` repeats for every model made from it, and is said once.
    notes: RefCell<BTreeMap<String, usize>>,
    /// Colours drawn for `color "random"`, for the next draw.
    randoms: Cell<u64>,
}

/// One line per warning, with its count when it concerns several models.
fn summarize(notes: &BTreeMap<String, usize>) -> Vec<String> {
    notes
        .iter()
        .map(|(msg, &n)| match n {
            1 => msg.clone(),
            n => format!("{msg} ({n} models)"),
        })
        .collect()
}

fn short(p: &Prop, name: &str, want: usize, form: &str) -> WorldError {
    WorldError {
        pos: p.pos.clone(),
        msg: format!(
            "`{name}` needs {want} values {form}, got {}",
            p.values.len()
        ),
    }
}

impl Reader {
    fn note(&self, msg: String) {
        *self.notes.borrow_mut().entry(msg).or_insert(0) += 1;
    }
    fn prop<'e>(&self, e: &'e Entity, name: &str) -> Option<&'e Prop> {
        e.props.get(name)
    }
    fn float(&self, e: &Entity, name: &str, default: f64) -> f64 {
        self.prop(e, name)
            .and_then(|p| p.values.first())
            .map_or(default, Val::num)
    }
    fn length(&self, e: &Entity, name: &str, default: f64) -> f64 {
        self.prop(e, name)
            .and_then(|p| p.values.first())
            .map_or(default, |v| v.num() * self.len)
    }
    fn angle(&self, e: &Entity, name: &str, default: f64) -> f64 {
        self.prop(e, name)
            .and_then(|p| p.values.first())
            .map_or(default, |v| v.num() * self.ang)
    }
    fn int(&self, e: &Entity, name: &str, default: i64) -> i64 {
        self.prop(e, name)
            .and_then(|p| p.values.first())
            .map_or(default, |v| v.num() as i64)
    }
    fn string(&self, e: &Entity, name: &str) -> Option<String> {
        self.prop(e, name)
            .and_then(|p| p.values.first())
            .map(|v| v.text().to_owned())
    }
    /// `pose`: Stage 4's `[x y z a]` or Stage 3's `[x y a]`.
    fn pose(&self, e: &Entity, name: &str) -> Result<Option<(Pose, f64)>, WorldError> {
        let Some(p) = self.prop(e, name) else {
            return Ok(None);
        };
        let v: Vec<f64> = p.values.iter().map(Val::num).collect();
        match v.len() {
            n if n >= 4 => Ok(Some((
                Pose::new(v[0] * self.len, v[1] * self.len, v[3] * self.ang),
                v[2] * self.len,
            ))),
            3 => Ok(Some((
                Pose::new(v[0] * self.len, v[1] * self.len, v[2] * self.ang),
                0.0,
            ))),
            _ => Err(short(p, name, 4, "[x y z a] (or Stage 3's [x y a])")),
        }
    }
    /// `size`: `[x y z]`, or `[x y]` keeping the default height.
    fn size(&self, e: &Entity, default: [f64; 3]) -> Result<[f64; 3], WorldError> {
        let Some(p) = self.prop(e, "size") else {
            return Ok(default);
        };
        let v: Vec<f64> = p.values.iter().map(|x| x.num() * self.len).collect();
        match v.len() {
            n if n >= 3 => Ok([v[0], v[1], v[2]]),
            2 => Ok([v[0], v[1], default[2]]),
            _ => Err(short(p, "size", 3, "[x y z]")),
        }
    }
    fn color(&self, e: &Entity, default: Color) -> Color {
        if let Some(name) = self.string(e, "color") {
            if name == "random" {
                // Stage draws one; here the n-th draw of a load is always the same.
                let n = self.randoms.get();
                self.randoms.set(n + 1);
                return colors::random(n);
            }
            return colors::lookup(&name).unwrap_or_else(|| {
                self.note(format!(
                    "{}: unknown colour \"{name}\"; using red, as Stage does",
                    e.props["color"].pos
                ));
                colors::RED
            });
        }
        match self.prop(e, "color_rgba") {
            Some(p) if p.values.len() >= 4 => {
                let c: Vec<f32> = p.values.iter().map(|v| v.num() as f32).collect();
                Color {
                    r: c[0],
                    g: c[1],
                    b: c[2],
                    a: c[3],
                }
            }
            _ => default,
        }
    }
    /// Stage's energy properties, read in Stage's order: `joules` fills a
    /// pack of that size, `joules_capacity` resizes it, then the same in
    /// kilojoules (a store above a new capacity is cut to it).
    fn energy(&self, e: &Entity) -> Energy {
        let mut pack: Option<(f64, f64)> = None;
        for (name, scale, fill) in [
            ("joules", 1.0, true),
            ("joules_capacity", 1.0, false),
            ("kjoules", 1000.0, true),
            ("kjoules_capacity", 1000.0, false),
        ] {
            if self.prop(e, name).is_none() {
                continue;
            }
            let (stored, capacity) = pack.unwrap_or_default();
            let j = scale * self.float(e, name, if fill { stored } else { capacity });
            pack = Some(if fill { (j, j) } else { (stored.min(j), j) });
        }
        Energy {
            pack,
            watts: self.float(e, "watts", 0.0),
            give: self.float(e, "give_watts", 0.0),
            take: self.float(e, "take_watts", 0.0),
            mass: self.float(e, "mass", 0.0),
            always_on: self.int(e, "alwayson", 0) != 0,
        }
    }
    fn bounds(&self, e: &Entity, name: &str, default: [f64; 8]) -> Result<[f64; 8], WorldError> {
        let Some(p) = self.prop(e, name) else {
            return Ok(default);
        };
        if p.values.len() < 8 {
            return Err(short(
                p,
                name,
                8,
                "[xmin xmax ymin ymax zmin zmax amin amax]",
            ));
        }
        let mut out = [0.0; 8];
        for (i, v) in p.values.iter().take(8).enumerate() {
            out[i] = v.num() * if i >= 6 { self.ang } else { self.len };
        }
        Ok(out)
    }
    /// A reader in the units the world's own settings give (`unit_length`, `unit_angle`).
    fn in_units_of(g: &Entity) -> Result<Self, WorldError> {
        Ok(Reader {
            len: unit(
                g,
                "unit_length",
                &[("m", 1.0), ("cm", 0.01), ("mm", 0.001)],
                1.0,
            )?,
            ang: unit(
                g,
                "unit_angle",
                &[("degrees", PI / 180.0), ("radians", 1.0)],
                PI / 180.0,
            )?,
            notes: RefCell::default(),
            randoms: Cell::new(0),
        })
    }
    /// Logs each warning once, with how many models it concerns.
    fn report_warnings(&self) {
        for line in summarize(&self.notes.borrow()) {
            tracing::warn!("{line}");
        }
    }
    /// A `block`'s outline (`points`, `point[i]`) and its `z` span.
    fn block(&self, e: &Entity) -> Result<(Polygon, (f64, f64)), WorldError> {
        let n = self.int(e, "points", 0).max(0) as usize;
        let mut pts = Vec::with_capacity(n);
        for i in 0..n {
            let name = format!("point[{i}]");
            let (x, y) = match e.props.get(name.as_str()) {
                Some(p) if p.values.len() >= 2 => {
                    (p.values[0].num() * self.len, p.values[1].num() * self.len)
                }
                Some(p) => return Err(short(p, &name, 2, "[x y]")),
                None => (0.0, 0.0),
            };
            pts.push((x, y));
        }
        let z = match e.props.get("z") {
            Some(p) if p.values.len() >= 2 => (p.values[0].num(), p.values[1].num()),
            Some(p) => return Err(short(p, "z", 2, "[min max]")),
            None => (0.0, 1.0),
        };
        Ok((pts, z))
    }
    /// A ranger's `sensor`.
    fn sensor(&self, e: &Entity) -> Result<Sensor, WorldError> {
        let (pose, z) = self.pose(e, "pose")?.unwrap_or_default();
        let range = match e.props.get("range") {
            Some(p) if p.values.len() >= 2 => {
                (p.values[0].num() * self.len, p.values[1].num() * self.len)
            }
            Some(p) => return Err(short(p, "range", 2, "[min max]")),
            None => (0.0, 5.0),
        };
        Ok(Sensor {
            pose,
            z,
            size: self.size(e, [0.02, 0.02, 0.02])?,
            range,
            fov: self.angle(e, "fov", 0.1),
            samples: self.int(e, "samples", 1).max(1) as usize,
        })
    }
    /// A position model's settings.
    fn position(&self, e: &Entity) -> Result<PositionCfg, WorldError> {
        let drive = self.drive(e);
        let localization = self.localization(e);
        let odom = self.odom_error(e)?;
        let half = PI / 2.0;
        Ok(PositionCfg {
            drive,
            velocity_bounds: self.bounds(
                e,
                "velocity_bounds",
                [-1.0, 1.0, -1.0, 1.0, -1.0, 1.0, -half, half],
            )?,
            acceleration_bounds: self.bounds(
                e,
                "acceleration_bounds",
                [-1.0, 1.0, -1.0, 1.0, -1.0, 1.0, -half, half],
            )?,
            localization,
            localization_origin: self.pose(e, "localization_origin")?.map(|(p, _)| p),
            odom_error: odom,
            wheelbase: self.length(e, "wheelbase", 1.0),
        })
    }
    /// `drive`: diff, omni or car (another name is warned of, and is diff).
    fn drive(&self, e: &Entity) -> Drive {
        match self.string(e, "drive").as_deref() {
            None | Some("diff") => Drive::Diff,
            Some("omni") => Drive::Omni,
            Some("car") => Drive::Car,
            Some(other) => {
                self.note(format!(
                    "{}: unknown drive \"{other}\" (diff, omni or car); using diff",
                    e.props["drive"].pos
                ));
                Drive::Diff
            }
        }
    }
    /// `localization`: gps or odom (another name is warned of, and is gps).
    fn localization(&self, e: &Entity) -> Localization {
        match self.string(e, "localization").as_deref() {
            None | Some("gps") => Localization::Gps,
            Some("odom") => Localization::Odom,
            Some(other) => {
                self.note(format!(
                    "{}: unknown localization \"{other}\" (gps or odom); using gps",
                    e.props["localization"].pos
                ));
                Localization::Gps
            }
        }
    }
    /// `odom_error`, if the model sets it.
    fn odom_error(&self, e: &Entity) -> Result<Option<[f64; 3]>, WorldError> {
        // As Stage's `Pose::Load` ("llla"): the turn's error is read
        // as an angle.
        match e.props.get("odom_error") {
            Some(p) if p.values.len() >= 4 => Ok(Some([
                p.values[0].num(),
                p.values[1].num(),
                p.values[3].num() * self.ang,
            ])),
            Some(p) if p.values.len() == 3 => Ok(Some([
                p.values[0].num(),
                p.values[1].num(),
                p.values[2].num() * self.ang,
            ])),
            Some(p) => Err(short(p, "odom_error", 4, "[x y z a]")),
            None => Ok(None),
        }
    }
    /// A blobfinder's settings.
    fn blobfinder(&self, e: &Entity) -> Result<BlobfinderCfg, WorldError> {
        let mut colors = Vec::new();
        if e.props.contains_key("colors") {
            let n = self.int(e, "colors_count", 0).max(0) as usize;
            let p = &e.props["colors"];
            if p.values.len() < n {
                return Err(short(p, "colors", n, "(one per colors_count)"));
            }
            for v in p.values.iter().take(n) {
                colors.push(colors::lookup(v.text()).unwrap_or(colors::RED));
            }
        }
        let image = match e.props.get("image") {
            Some(p) if p.values.len() >= 2 => (
                p.values[0].num().max(1.0) as u32,
                p.values[1].num().max(1.0) as u32,
            ),
            Some(p) => return Err(short(p, "image", 2, "[width height]")),
            None => (80, 60),
        };
        Ok(BlobfinderCfg {
            colors,
            image,
            range: self.float(e, "range", 12.0),
            fov: self.angle(e, "fov", PI / 3.0),
            pan: self.angle(e, "pan", 0.0),
        })
    }
    /// A fiducial detector's settings.
    fn fiducial(&self, e: &Entity) -> FiducialCfg {
        FiducialCfg {
            range_min: self.length(e, "range_min", 0.0),
            range_max: self.length(e, "range_max", 8.0),
            range_max_id: self.length(e, "range_max_id", 5.0),
            fov: self.angle(e, "fov", PI),
        }
    }
    /// A camera's settings.
    fn camera(&self, e: &Entity) -> Result<CameraCfg, WorldError> {
        let pair = |name: &str, default: (f64, f64), what: &str| match e.props.get(name) {
            Some(p) if p.values.len() >= 2 => Ok((p.values[0].num(), p.values[1].num())),
            Some(p) => Err(short(p, name, 2, what)),
            None => Ok(default),
        };
        let (w, h) = pair("resolution", (32.0, 32.0), "[width height]")?;
        let (near, far) = pair("range", (0.2, 8.0), "[min max]")?;
        let (hfov, vfov) = pair("fov", (70.0, 40.0), "[horizontal vertical]")?;
        let (pan, tilt) = pair("pantilt", (0.0, 0.0), "[pan tilt]")?;
        let pixels = |v: f64| v.clamp(1.0, 4096.0) as u32;
        let fov = |v: f64| v.clamp(1.0, 179.0).to_radians();
        Ok(CameraCfg {
            resolution: (pixels(w), pixels(h)),
            range: (near.max(1e-3), far.max(near.max(1e-3) + 1e-3)),
            fov: (fov(hfov), fov(vfov)),
            pantilt: (pan.to_radians(), tilt.to_radians()),
        })
    }
    /// `ctrl`: the model's controllers, each with its arguments.
    fn ctrl(&self, e: &Entity) -> Vec<String> {
        match self.prop(e, "ctrl") {
            Some(p) => p.values.iter().map(|v| v.text().to_owned()).collect(),
            None => Vec::new(),
        }
    }
    /// The sensors Stage 3 sets on the model itself: a `laser`'s one, a ranger's `scount`.
    fn stage3_sensors(&self, e: &Entity, kind: Kind) -> Result<Vec<Sensor>, WorldError> {
        let mut sensors = Vec::new();
        if e.kind == "laser" {
            sensors.push(self.stage3_laser(e));
        }
        // Stage 3 ranger: scount / spose[i] / sview[i] / ssize[i].
        if kind == Kind::Ranger {
            let n = self.int(e, "scount", 0).max(0) as usize;
            for i in 0..n {
                sensors.push(self.stage3_sonar(e, i)?);
            }
        }
        Ok(sensors)
    }
    /// Stage 3: a laser is one sensor with these properties on the model.
    fn stage3_laser(&self, e: &Entity) -> Sensor {
        let skip = self.int(e, "laser_sample_skip", 1).max(1) as usize;
        Sensor {
            pose: Pose::default(),
            z: 0.0,
            size: [0.02, 0.02, 0.02],
            range: (
                self.length(e, "range_min", 0.0),
                self.length(e, "range_max", 8.0),
            ),
            fov: self.angle(e, "fov", PI),
            samples: (self.int(e, "samples", 361).max(1) as usize).div_ceil(skip),
        }
    }
    /// Stage 3 ranger's sensor `i` (`spose[i]`, `sview[i]` or `sview`).
    fn stage3_sonar(&self, e: &Entity, i: usize) -> Result<Sensor, WorldError> {
        let sp = e.props.get(format!("spose[{i}]").as_str());
        let pose = match sp {
            Some(p) if p.values.len() >= 3 => Pose::new(
                p.values[0].num() * self.len,
                p.values[1].num() * self.len,
                p.values[2].num() * self.ang,
            ),
            Some(p) => return Err(short(p, &format!("spose[{i}]"), 3, "[x y a]")),
            None => Pose::default(),
        };
        let view = e
            .props
            .get(format!("sview[{i}]").as_str())
            .or_else(|| e.props.get("sview"));
        let (range, fov) = match view {
            Some(p) if p.values.len() >= 3 => (
                (p.values[0].num() * self.len, p.values[1].num() * self.len),
                p.values[2].num() * self.ang,
            ),
            Some(p) => return Err(short(p, "sview", 3, "[min max fov]")),
            None => ((0.0, 5.0), 0.1),
        };
        Ok(Sensor {
            pose,
            z: 0.0,
            size: [0.02, 0.02, 0.02],
            range,
            fov,
            samples: 1,
        })
    }
    /// A model's body as the file draws it (Stage 2 polygons, a bitmap), or
    /// Stage's default: a square, or a gripper's back and paddles.
    fn body(&self, e: &Entity, kind: Kind, dir: &Path) -> Result<Body, WorldError> {
        let mut blocks = Vec::new();
        let mut default_block = matches!(
            kind,
            Kind::Model | Kind::Position | Kind::Bumper | Kind::Other
        );
        if self.int(e, "noblocks", 0) != 0 {
            default_block = false;
        }
        // Stage 2: polygons N with polygon[i].points and polygon[i].point[j].
        let np = self.int(e, "polygons", 0).max(0) as usize;
        for i in 0..np {
            let poly = self.polygon(e, i)?;
            if poly.len() >= 2 {
                blocks.push(poly);
                default_block = false;
            }
        }
        if let Some(cells) = self.bitmap(e, dir)? {
            blocks.extend(cells);
            default_block = false;
        }
        if default_block {
            blocks.push(rect(-0.5, -0.5, 0.5, 0.5));
        } else if kind == Kind::Gripper && blocks.is_empty() && self.int(e, "noblocks", 0) == 0 {
            // Stage's gripper body: a block at the back and two paddles
            // (0.66 of its length, 0.1 of its width each), drawn open.
            blocks.push(rect(0.0, 0.0, 0.34, 1.0));
            blocks.push(rect(0.34, 0.0, 1.0, 0.1));
            blocks.push(rect(0.34, 0.9, 1.0, 1.0));
        }
        Ok(Body {
            z: vec![(0.0, 1.0); blocks.len()],
            blocks,
            default_block,
            boundary: self.int(e, "boundary", 0) != 0,
        })
    }
    /// Stage 2's polygon `i` (`polygon[i].points`, `polygon[i].point[j]`).
    fn polygon(&self, e: &Entity, i: usize) -> Result<Polygon, WorldError> {
        let pts = self.int(e, &format!("polygon[{i}].points"), 0).max(0) as usize;
        let mut poly = Vec::new();
        for j in 0..pts {
            let key = format!("polygon[{i}].point[{j}]");
            match e.props.get(key.as_str()) {
                Some(p) if p.values.len() >= 2 => {
                    poly.push((p.values[0].num() * self.len, p.values[1].num() * self.len))
                }
                Some(p) => return Err(short(p, &key, 2, "[x y]")),
                None => poly.push((0.0, 0.0)),
            }
        }
        Ok(poly)
    }
    /// The `bitmap`'s dark cells (found beside the world file), one rectangle each.
    fn bitmap(&self, e: &Entity, dir: &Path) -> Result<Option<Vec<Polygon>>, WorldError> {
        let Some(file) = self.string(e, "bitmap") else {
            return Ok(None);
        };
        let p = if Path::new(&file).is_absolute() {
            file.clone().into()
        } else {
            dir.join(&file)
        };
        let bmp = Bitmap::load(&p).map_err(|err| WorldError {
            pos: e.props["bitmap"].pos.clone(),
            msg: err.to_string(),
        })?;
        let mut cells = Vec::new();
        for rc in bmp.dark_rects(128) {
            // Image rows grow downwards; the world's y grows upwards.
            let (x0, x1) = (f64::from(rc.x), f64::from(rc.x + rc.w));
            let (y0, y1) = (-f64::from(rc.y + rc.h), -f64::from(rc.y));
            cells.push(rect(x0, y0, x1, y1));
        }
        Ok(Some(cells))
    }
}

fn kind_of(e: &Entity) -> Result<Option<Kind>, WorldError> {
    Ok(Some(match e.kind.as_str() {
        "model" => Kind::Model,
        "position" => Kind::Position,
        "ranger" | "laser" => Kind::Ranger,
        "blobfinder" => Kind::Blobfinder,
        "fiducial" => Kind::Fiducial,
        "gripper" => Kind::Gripper,
        "bumper" => Kind::Bumper,
        "camera" => Kind::Camera,
        "actuator" | "blinkenlight" | "lightindicator" => Kind::Other,
        "window" | "block" | "sensor" => return Ok(None),
        other => {
            return Err(WorldError {
                pos: e.pos.clone(),
                msg: format!(
                    "unknown model type `{other}`; Stage 4 knows model, position, ranger (with sensor), blobfinder, fiducial, gripper, bumper, camera, actuator, blinkenlight, lightindicator (and Stage 3's laser)"
                ),
            })
        }
    }))
}

/// Scales polygons so their bounding box is `size` (x, y), centred on (0, 0).
/// Stage's `canonicalize_winding`: a block's points are reversed unless
/// their turns sum to a positive angle (counter-clockwise, as OpenGL
/// wants). The order decides which side of each edge Stage's 4-connected
/// outline steps to, so a ray meets a clockwise block's cells one cell
/// sooner or later than the file's order would draw them.
fn canonicalize_winding(pts: &mut [(f64, f64)]) {
    use std::f64::consts::{PI, TAU};
    let n = pts.len();
    let v: Vec<(f64, f64)> = (0..n)
        .map(|i| {
            let (a, b) = (pts[i], pts[(i + 1) % n]);
            (b.0 - a.0, b.1 - a.1)
        })
        .collect();
    let heading = |p: (f64, f64)| {
        let a = p.1.atan2(p.0);
        if a < 0.0 {
            a + TAU
        } else {
            a
        }
    };
    let mut sum = 0.0;
    for i in 0..n {
        let mut turn = heading(v[(i + 1) % n]) - heading(v[i]);
        while turn < -PI {
            turn += TAU;
        }
        while PI < turn {
            turn -= TAU;
        }
        sum += turn;
    }
    if sum <= 0.0 {
        pts.reverse();
    }
}

fn stretch(blocks: &mut [Vec<(f64, f64)>], sx: f64, sy: f64) {
    let Some([x0, y0, x1, y1]) = bounds(blocks.iter().flatten().copied()) else {
        return;
    };
    let (ex, ey) = ((x1 - x0).max(f64::EPSILON), (y1 - y0).max(f64::EPSILON));
    let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
    for p in blocks.iter_mut().flatten() {
        p.0 = (p.0 - cx) * sx / ex;
        p.1 = (p.1 - cy) * sy / ey;
    }
}

/// Blocks' heights scaled to a model `sz` high, as Stage's
/// `BlockGroup::CalcSize` scales them: by `sz` over their extent, from 0
/// (not from the lowest base: blocks from 0.5 to 1 of a model 1 m high
/// span 1 to 2 m, in Stage as here).
fn stretch_z(z: &mut [(f64, f64)], sz: f64) {
    let lo = z.iter().map(|b| b.0).fold(f64::INFINITY, f64::min);
    let hi = z.iter().map(|b| b.1).fold(f64::NEG_INFINITY, f64::max);
    let k = sz / (hi - lo).max(f64::EPSILON);
    for b in z {
        *b = (b.0 * k, b.1 * k);
    }
}

fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Vec<(f64, f64)> {
    vec![(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
}

/// The factor the world's unit setting `name` picks from `table` (`default` when unset).
fn unit(g: &Entity, name: &str, table: &[(&str, f64)], default: f64) -> Result<f64, WorldError> {
    match g.props.get(name) {
        None => Ok(default),
        Some(p) => {
            let t = p.values.first().map(Val::text).unwrap_or("");
            table
                .iter()
                .find(|(n, _)| *n == t)
                .map(|(_, f)| *f)
                .ok_or_else(|| WorldError {
                    pos: p.pos.clone(),
                    msg: format!(
                        "{name} must be one of {}",
                        table
                            .iter()
                            .map(|(n, _)| format!("\"{n}\""))
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                })
        }
    }
}

/// The world's own settings (resolution, step, quit time, speed…), with no models yet.
fn world_settings(r: &Reader, g: &Entity) -> World {
    World {
        resolution: r.float(g, "resolution", 0.02).max(1e-4),
        interval_sim: r.float(g, "interval_sim", 100.0).max(1.0) / 1000.0,
        quit_time: r.float(g, "quit_time", 0.0).max(0.0),
        speedup: r.float(g, "speedup", 1.0),
        threads: r.int(g, "threads", 1).max(1) as usize,
        paused: r.int(g, "paused", 0) != 0,
        models: Vec::new(),
        names: HashMap::new(),
    }
}

/// A model's size when the file gives none, by type (Stage's defaults).
fn default_size(kind: Kind) -> [f64; 3] {
    match kind {
        Kind::Ranger => [0.15, 0.15, 0.2],
        Kind::Gripper => [0.2, 0.3, 0.2],
        Kind::Fiducial => [0.0, 0.0, 0.0],
        Kind::Camera => [0.1, 0.07, 0.05],
        _ => [0.4, 0.4, 1.0],
    }
}

/// A model's colour when the file gives none, by type (Stage's defaults).
fn default_color(kind: Kind) -> Color {
    match kind {
        Kind::Ranger => Color {
            r: 0.0,
            g: 0.0,
            b: 0.5,
            a: 1.0,
        },
        _ => colors::RED,
    }
}

/// Box `i` of the `dynamic` controller on model `m` (`parent`): blue, 10 cm,
/// somewhere within a metre of the model's centre, facing any way.
fn dynamic_box(parent: &ModelDef, m: usize, i: u64, name: String) -> ModelDef {
    let draw = |k: u64| colors::unit_draw([m as u64, i, k]);
    let blue = Color {
        r: 0.0,
        g: 0.0,
        b: 1.0,
        a: 1.0,
    };
    ModelDef {
        name,
        kind: Kind::Model,
        parent: Some(m),
        children: Vec::new(),
        pose: Pose::new(
            -1.0 + 2.0 * draw(0),
            -1.0 + 2.0 * draw(1),
            troupe_geom::normalize(2.0 * PI * draw(2)),
        ),
        z: 0.0,
        size: [0.1, 0.1, 0.1],
        origin: Pose::default(),
        color: blue,
        blocks: Vec::new(),
        block_z: Vec::new(),
        position: None,
        sensors: Vec::new(),
        ctrl: Vec::new(),
        blobfinder: None,
        fiducial: None,
        camera: None,
        energy: Energy::default(),
        update_interval: 0.1,
        obstacle_return: true,
        ranger_return: 1.0,
        blob_return: true,
        fiducial_return: 0,
        gripper_return: false,
        stack_children: true,
        map_resolution: 0.1,
        pos: parent.pos.clone(),
    }
}

/// Loads the world file at `path`.
///
/// # Errors
///
/// A syntax error, an unknown model type, a too-short tuple or a missing
/// bitmap, each with file:line:column.
pub fn load(path: &Path) -> Result<World, WorldError> {
    let wf = worldfile::parse(path)?;
    let globals = &wf.entities[0];
    let r = Reader::in_units_of(globals)?;
    let world = world_settings(&r, globals);
    let mut loader = Loader::new(r, world, path);
    for (ei, e) in wf.entities.iter().enumerate().skip(1) {
        loader.read_entity(ei, e)?;
    }
    loader.add_dynamic_boxes();
    loader.fit_bodies();
    loader.r.report_warnings();
    Ok(loader.world)
}

/// A model's body as the file draws it, before it is fitted to the model's size.
struct Body {
    /// Polygons as drawn (metres, or a bitmap's pixels).
    blocks: Vec<Polygon>,
    /// Each block's `z`, in the same order.
    z: Vec<(f64, f64)>,
    /// The blocks are Stage's default square, which a `block` replaces.
    default_block: bool,
    /// Walls go along its edges (`boundary`).
    boundary: bool,
}

/// What loading keeps from one entity to the next.
struct Loader<'a> {
    /// Reads properties in the world's units, and keeps its warnings.
    r: Reader,
    /// The world so far.
    world: World,
    /// Each model's body until all are read, in model order.
    bodies: Vec<Body>,
    /// Entity index → model index.
    model_of: HashMap<usize, usize>,
    /// Models made so far of each type under each parent, for `type:n` names.
    counts: HashMap<(Option<usize>, String), usize>,
    /// The world file's directory, where bitmaps are found.
    dir: &'a Path,
}

impl<'a> Loader<'a> {
    /// A loader filling `world`, read from the file at `path`.
    fn new(r: Reader, world: World, path: &'a Path) -> Self {
        Loader {
            r,
            world,
            bodies: Vec::new(),
            model_of: HashMap::new(),
            // Stage's world makes its ground, a top-level `model`, before the
            // file's: unnamed top-level models count from `model:1`.
            counts: HashMap::from([((None, "model".to_owned()), 1)]),
            dir: path.parent().unwrap_or(Path::new(".")),
        }
    }

    /// Reads entity `ei`: a model, or a block or sensor of the model it is in.
    fn read_entity(&mut self, ei: usize, e: &Entity) -> Result<(), WorldError> {
        let parent = e.parent.and_then(|p| self.model_of.get(&p).copied());
        match e.kind.as_str() {
            "window" => Ok(()),
            "block" => self.add_block(e, parent),
            "sensor" => self.add_sensor(e, parent),
            _ => match kind_of(e)? {
                Some(kind) => self.add_model(ei, e, kind, parent),
                None => Ok(()),
            },
        }
    }

    /// Adds a `block` to its model's body (the first replaces the default square).
    fn add_block(&mut self, e: &Entity, parent: Option<usize>) -> Result<(), WorldError> {
        let Some(m) = parent else {
            return Err(WorldError {
                pos: e.pos.clone(),
                msg: "a `block` must be inside a model".into(),
            });
        };
        let (mut pts, z) = self.r.block(e)?;
        if pts.len() >= 2 {
            let body = &mut self.bodies[m];
            if body.default_block {
                body.blocks.clear();
                body.z.clear();
                body.default_block = false;
            }
            canonicalize_winding(&mut pts);
            body.blocks.push(pts);
            body.z.push(z);
        }
        Ok(())
    }

    /// Adds a `sensor` to the ranger it is in.
    fn add_sensor(&mut self, e: &Entity, parent: Option<usize>) -> Result<(), WorldError> {
        let Some(m) = parent.filter(|&m| self.world.models[m].kind == Kind::Ranger) else {
            return Err(WorldError {
                pos: e.pos.clone(),
                msg: "a `sensor` must be inside a ranger".into(),
            });
        };
        let sensor = self.r.sensor(e)?;
        self.world.models[m].sensors.push(sensor);
        Ok(())
    }

    /// Adds the model entity `ei` describes, under `parent`, by both its names.
    fn add_model(
        &mut self,
        ei: usize,
        e: &Entity,
        kind: Kind,
        parent: Option<usize>,
    ) -> Result<(), WorldError> {
        let idx = self.world.models.len();
        self.model_of.insert(ei, idx);
        let (auto, name) = self.names(e, parent);
        let (def, body) = self.read_model(e, kind, parent, name.clone())?;
        self.world.models.push(def);
        self.bodies.push(body);
        if let Some(p) = parent {
            self.world.models[p].children.push(idx);
        }
        self.world.names.insert(auto, idx);
        self.world.names.insert(name, idx);
        Ok(())
    }

    /// The name Stage gives a new model (`type:n` among its siblings) and the
    /// name it goes by (its `name`, under its parent's), in that order.
    fn names(&mut self, e: &Entity, parent: Option<usize>) -> (String, String) {
        // Names: `type:n` among siblings, or the given name (children: parent.name).
        let k = self.counts.entry((parent, e.kind.clone())).or_insert(0);
        let parent_name = parent.map(|p| self.world.models[p].name.clone());
        let auto = match &parent_name {
            Some(pn) => format!("{pn}.{}:{}", e.kind, k),
            None => format!("{}:{}", e.kind, k),
        };
        *k += 1;
        let name = match self.r.string(e, "name") {
            Some(n) if n.starts_with('/') => n[1..].to_owned(),
            Some(n) => match &parent_name {
                Some(pn) => format!("{pn}.{n}"),
                None => n,
            },
            None => auto.clone(),
        };
        (auto, name)
    }

    /// Model `name` of type `kind` as entity `e` describes it, and its body.
    fn read_model(
        &self,
        e: &Entity,
        kind: Kind,
        parent: Option<usize>,
        name: String,
    ) -> Result<(ModelDef, Body), WorldError> {
        let r = &self.r;
        let size = r.size(e, default_size(kind))?;
        let (pose, z) = r.pose(e, "pose")?.unwrap_or_default();
        let origin = r.pose(e, "origin")?.map(|(p, _)| p).unwrap_or_default();
        let position = (kind == Kind::Position)
            .then(|| r.position(e))
            .transpose()?;
        let blobfinder = (kind == Kind::Blobfinder)
            .then(|| r.blobfinder(e))
            .transpose()?;
        let fiducial = (kind == Kind::Fiducial).then(|| r.fiducial(e));
        let camera = (kind == Kind::Camera).then(|| r.camera(e)).transpose()?;
        let ctrl = r.ctrl(e);
        let sensors = r.stage3_sensors(e, kind)?;
        let body = r.body(e, kind, self.dir)?;
        let def = ModelDef {
            name,
            kind,
            parent,
            children: Vec::new(),
            pose,
            z,
            size,
            origin,
            color: r.color(e, default_color(kind)),
            blocks: Vec::new(),
            block_z: Vec::new(),
            obstacle_return: r.int(e, "obstacle_return", 1) != 0,
            ranger_return: r.float(e, "ranger_return", 1.0),
            blob_return: r.int(e, "blob_return", 1) != 0,
            fiducial_return: r.int(e, "fiducial_return", 0) as i32,
            gripper_return: r.int(e, "gripper_return", 0) != 0,
            stack_children: r.int(e, "stack_children", 1) != 0,
            map_resolution: r.length(e, "map_resolution", 0.1),
            position,
            sensors,
            ctrl,
            update_interval: r.float(e, "update_interval", 100.0).max(1.0) / 1000.0,
            energy: r.energy(e),
            blobfinder,
            fiducial,
            camera,
            pos: e.pos.clone(),
        };
        Ok((def, body))
    }

    /// Stage's `dynamic` controller: at start-up, 100 blue 10 cm boxes on
    /// its model, anywhere within a metre of its centre, facing any way
    /// (Stage draws them at random; here the same on every load).
    fn add_dynamic_boxes(&mut self) {
        for m in 0..self.world.models.len() {
            let ctrl = &self.world.models[m].ctrl;
            if !ctrl
                .iter()
                .any(|c| c.split_whitespace().next() == Some("dynamic"))
            {
                continue;
            }
            for i in 0..100u64 {
                self.add_box(m, i);
            }
        }
    }

    /// Adds box `i` of the `dynamic` controller on model `m`.
    fn add_box(&mut self, m: usize, i: u64) {
        let k = self
            .counts
            .entry((Some(m), "model".to_owned()))
            .or_insert(0);
        let name = format!("{}.model:{k}", self.world.models[m].name);
        *k += 1;
        let idx = self.world.models.len();
        let child = dynamic_box(&self.world.models[m], m, i, name.clone());
        self.world.models.push(child);
        self.world.models[m].children.push(idx);
        self.bodies.push(Body {
            blocks: vec![rect(-0.5, -0.5, 0.5, 0.5)],
            z: vec![(0.0, 1.0)],
            default_block: true,
            boundary: false,
        });
        self.world.names.insert(name, idx);
    }

    /// Bodies: stretch to size, add boundary walls, apply the origin.
    fn fit_bodies(&mut self) {
        for (m, body) in std::mem::take(&mut self.bodies).into_iter().enumerate() {
            let Body {
                mut blocks,
                mut z,
                boundary,
                ..
            } = body;
            let [sx, sy, sz] = self.world.models[m].size;
            stretch(&mut blocks, sx, sy);
            stretch_z(&mut z, sz);
            if boundary {
                let (hx, hy, t) = (sx / 2.0, sy / 2.0, 0.01);
                blocks.push(rect(-hx, -hy, -hx + t, hy));
                blocks.push(rect(-hx, -hy, hx, -hy + t));
                blocks.push(rect(-hx, hy - t, hx, hy));
                blocks.push(rect(hx - t, -hy, hx, hy));
                z.extend([(0.0, sz); 4]);
            }
            let o = self.world.models[m].origin;
            for b in &mut blocks {
                for p in b.iter_mut() {
                    *p = o.apply(p.0, p.1);
                }
            }
            self.world.models[m].blocks = blocks;
            self.world.models[m].block_z = z;
        }
    }
}

impl World {
    /// The global pose of model `m` and its height, from the per-model relative `poses`.
    pub fn global(&self, poses: &[Pose], m: usize) -> (Pose, f64) {
        let def = &self.models[m];
        match def.parent {
            None => (poses[m], def.z),
            Some(p) => {
                let (gp, gz) = self.global(poses, p);
                let stack = if self.models[p].stack_children {
                    self.models[p].size[2]
                } else {
                    0.0
                };
                (gp.compose(&poses[m]), gz + def.z + stack)
            }
        }
    }

    /// The top-level ancestor of model `m`.
    pub fn root(&self, mut m: usize) -> usize {
        while let Some(p) = self.models[m].parent {
            m = p;
        }
        m
    }

    /// Model `base` and its descendants, depth-first in file order.
    pub fn subtree(&self, base: usize) -> Vec<usize> {
        let mut out = vec![base];
        let mut i = 0;
        while i < out.len() {
            let kids = self.models[out[i]].children.clone();
            out.splice(i + 1..i + 1, kids);
            i += 1;
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_wind_counter_clockwise_as_stage_makes_them() {
        // Stage's sick.inc lists its box clockwise; Stage reverses it.
        let mut cw = vec![(0.0, 0.0), (0.0, 1.0), (1.0, 1.0), (1.0, 0.0)];
        canonicalize_winding(&mut cw);
        assert_eq!(cw, [(1.0, 0.0), (1.0, 1.0), (0.0, 1.0), (0.0, 0.0)]);
        let ccw = vec![(0.0, 0.0), (1.0, 0.0), (1.0, 1.0)];
        let mut same = ccw.clone();
        canonicalize_winding(&mut same);
        assert_eq!(same, ccw);
    }

    fn load_text(name: &str, text: &str) -> Result<World, WorldError> {
        let dir = std::env::temp_dir().join(format!("troupe-world-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("t.world");
        std::fs::write(&p, text).unwrap();
        let r = load(&p);
        let _ = std::fs::remove_dir_all(&dir);
        r
    }

    #[test]
    fn dynamic_makes_its_hundred_boxes_on_its_model() {
        let text = "model ( name \"base\" pose [5 5 0 0] size [3 3 0.2] ctrl \"dynamic\" )\n";
        let w = load_text("dynamic", text).unwrap();
        let base = w.names["base"];
        let kids = &w.models[base].children;
        assert_eq!(kids.len(), 100);
        assert_eq!(w.names["base.model:99"], kids[99]);
        for &k in kids {
            let c = &w.models[k];
            assert_eq!((c.parent, c.size), (Some(base), [0.1, 0.1, 0.1]));
            assert!(c.pose.x.abs() <= 1.0 && c.pose.y.abs() <= 1.0);
            assert_eq!(c.blocks.len(), 1);
        }
        let spread = kids.iter().map(|&k| w.models[k].pose.x).fold(0.0, f64::max);
        assert!(spread > 0.8, "boxes spread over the metre: {spread}");
    }

    #[test]
    fn power_packs_read_in_stages_order() {
        let text = "model ( name \"a\" kjoules 5 )\n\
                    model ( name \"b\" joules 900 joules_capacity 500 )\n\
                    model ( name \"c\" joules -1 give_watts 2000 alwayson 1 )\n\
                    position ( name \"d\" mass 23 model ( take_watts 100 watts 3 ) )\n";
        let w = load_text("energy", text).unwrap();
        let e = |n: &str| w.models[w.names[n]].energy.clone();
        assert_eq!(e("a").pack, Some((5000.0, 5000.0)));
        assert_eq!(e("b").pack, Some((500.0, 500.0)));
        assert_eq!(e("c").pack, Some((-1.0, -1.0)));
        assert!(e("c").always_on && e("c").give == 2000.0);
        assert_eq!((e("d").mass, e("d").pack), (23.0, None));
        let bump = e("d.model:0");
        assert_eq!((bump.take, bump.watts), (100.0, 3.0));
    }

    #[test]
    fn random_colours_differ_between_models_and_repeat_between_loads() {
        let text = "define thing model ( color \"random\" size [1 1 1] )\n\
                    thing ( name \"a\" pose [0 0 0 0] )\n\
                    thing ( name \"b\" pose [2 0 0 0] )\n\
                    thing ( name \"c\" pose [4 0 0 0] )\n";
        let colours = |w: &World| -> Vec<Color> {
            ["a", "b", "c"]
                .iter()
                .map(|n| w.models[w.names[*n]].color)
                .collect()
        };
        let first = colours(&load_text("random1", text).unwrap());
        assert_ne!(first[0], first[1]);
        assert_ne!(first[1], first[2]);
        assert!(first.iter().all(|c| c.a == 1.0 && c != &colors::RED));
        assert_eq!(first, colours(&load_text("random2", text).unwrap()));
    }

    #[test]
    fn a_warning_shared_by_many_models_is_one_line_with_a_count() {
        let notes: BTreeMap<String, usize> = [
            ("h.world:3:9: unknown colour \"x\"".to_owned(), 1000),
            ("h.world:9:2: unknown drive \"y\"".to_owned(), 1),
        ]
        .into_iter()
        .collect();
        assert_eq!(
            summarize(&notes),
            [
                "h.world:3:9: unknown colour \"x\" (1000 models)",
                "h.world:9:2: unknown drive \"y\"",
            ]
        );
    }

    /// As Stage names them: everything.world's three pucks, after the
    /// named floor plan, are `model:2`..`model:4` (Stage's ground is
    /// `model` number 0); children count among their siblings.
    #[test]
    fn unnamed_models_are_named_as_stage_names_them() {
        let w = load_text(
            "names",
            "define puck model ( size [0.08 0.08 0.1] )\n\
             model ( name \"hospital\" size [4 4 0.6] )\n\
             puck( pose [1 0 0 0] ) puck( pose [2 0 0 0] ) puck( pose [3 0 0 0] )\n\
             position ( name \"r0\" pose [0 1 0 0] ranger( ) ranger( ) )\n",
        )
        .unwrap();
        for n in [
            "model:2",
            "model:3",
            "model:4",
            "r0.ranger:0",
            "r0.ranger:1",
        ] {
            assert!(w.names.contains_key(n), "{n} not in {:?}", w.names.keys());
        }
        // As in Stage, a named model also answers to the name it was born with.
        assert_eq!(w.names.get("model:1"), w.names.get("hospital"));
    }

    #[test]
    fn models_names_poses_sizes_and_sensors() {
        let w = load_text(
            "basic",
            "interval_sim 50\nquit_time 10\n\
             define laser_ranger ranger ( sensor( range [0 8] fov 180 samples 181 ) )\n\
             position ( name \"r0\" pose [1 2 0 90] size [0.5 0.4 0.2] drive \"omni\"\n\
               ranger( sensor( pose [0.1 0 0 0] ) sensor( pose [0 0.1 0 90] ) )\n\
               laser_ranger( pose [0.2 0 0 0] ) )\n\
             model ( name \"box\" pose [3 3 0] size [1 1] )\n",
        )
        .unwrap();
        assert_eq!(w.interval_sim, 0.05);
        assert_eq!(w.quit_time, 10.0);
        let r0 = w.names["r0"];
        let m = &w.models[r0];
        assert_eq!(m.kind, Kind::Position);
        assert!((m.pose.yaw - PI / 2.0).abs() < 1e-12);
        assert_eq!(m.position.as_ref().unwrap().drive, Drive::Omni);
        assert_eq!(m.children.len(), 2);
        let sonar = &w.models[w.names["r0.ranger:0"]];
        assert_eq!(sonar.sensors.len(), 2);
        let laser = &w.models[w.names["r0.ranger:1"]];
        assert_eq!(laser.sensors[0].samples, 181);
        assert!((laser.sensors[0].fov - PI).abs() < 1e-12);
        // The default body is stretched to the size.
        let b = &m.blocks[0];
        assert!(
            b.iter()
                .any(|p| (p.0 - 0.25).abs() < 1e-12 && (p.1 - 0.2).abs() < 1e-12),
            "{b:?}"
        );
        // Stage 3 pose [x y a] and size [x y].
        let bx = &w.models[w.names["box"]];
        assert_eq!((bx.pose.x, bx.pose.y), (3.0, 3.0));
        assert_eq!(bx.size, [1.0, 1.0, 1.0]);
        // Global pose of the laser: r0 at (1,2) facing +y, laser 0.2 ahead.
        let poses: Vec<Pose> = w.models.iter().map(|m| m.pose).collect();
        let (g, _) = w.global(&poses, w.names["r0.ranger:1"]);
        assert!((g.x - 1.0).abs() < 1e-9 && (g.y - 2.2).abs() < 1e-9);
    }

    #[test]
    fn bad_worlds_say_where_and_what() {
        let e = load_text("type", "robot ( )").unwrap_err().to_string();
        assert!(e.contains(":1:1: unknown model type `robot`"), "{e}");
        let e = load_text("size", "model ( size [1] )")
            .unwrap_err()
            .to_string();
        assert!(e.contains("`size` needs 3 values"), "{e}");
        let e = load_text("bitmap", "model ( bitmap \"nope.png\" )")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(":1:9: cannot load bitmap") && e.contains("nope.png"),
            "{e}"
        );
        let e = load_text("sensor", "model ( sensor ( ) )")
            .unwrap_err()
            .to_string();
        assert!(e.contains("a `sensor` must be inside a ranger"), "{e}");
        let e = load_text("units", "unit_length \"feet\"")
            .unwrap_err()
            .to_string();
        assert!(e.contains("unit_length must be one of"), "{e}");
    }

    #[test]
    fn stage3_forms_load() {
        let w = load_text(
            "stage3",
            "laser ( name \"l\" range_max 4 fov 90 samples 91 laser_sample_skip 2 )\n\
             ranger ( name \"s\" scount 2 spose[0] [0.1 0 0] spose[1] [0 0.1 90] sview [0 5 15] )\n\
             model ( name \"p\" polygons 1 polygon[0].points 3 polygon[0].point[0] [0 0] polygon[0].point[1] [1 0] polygon[0].point[2] [0 1] )\n",
        )
        .unwrap();
        let l = &w.models[w.names["l"]];
        assert_eq!(l.kind, Kind::Ranger);
        assert_eq!(l.sensors[0].samples, 46);
        assert_eq!(l.sensors[0].range.1, 4.0);
        assert_eq!(w.models[w.names["s"]].sensors.len(), 2);
        assert_eq!(w.models[w.names["p"]].blocks[0].len(), 3);
    }
}

/// Every world of ../shared/compat/stage loads, or says exactly what is missing.
#[cfg(test)]
mod compat {
    use super::*;

    #[test]
    fn every_compat_world_loads_or_names_the_missing_file() {
        let Some(dir) = troupe_node::testing::compat("stage") else {
            return;
        };
        let mut worlds: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .flatten()
            .map(|e| e.path())
            .filter(|p| p.extension().is_some_and(|e| e == "world"))
            .collect();
        worlds.sort();
        assert!(worlds.len() >= 7);
        for w in worlds {
            let name = w.file_name().unwrap().to_string_lossy().into_owned();
            match (name.as_str(), load(&w)) {
                // These two name files the compat set does not ship.
                ("autolab.world", Err(e)) => {
                    assert!(e.to_string().contains("chatterbox.inc"), "{e}")
                }
                ("large.world", Err(e)) => {
                    assert!(e.to_string().contains("SFU_1200x615.png"), "{e}")
                }
                (_, Err(e)) => panic!("{name}: {e}"),
                (_, Ok(world)) => {
                    assert!(!world.models.is_empty(), "{name}");
                    for m in &world.models {
                        for b in &m.blocks {
                            assert!(
                                b.iter().all(|p| p.0.is_finite() && p.1.is_finite()),
                                "{name}: {}",
                                m.name
                            );
                        }
                    }
                }
            }
        }
        // simple.world as the plugin sees it: r0's sonar is ranger:0, the laser ranger:1.
        let w = load(&dir.join("simple.world")).unwrap();
        let sonar = &w.models[w.names["r0.ranger:0"]];
        let laser = &w.models[w.names["r0.ranger:1"]];
        assert_eq!(sonar.sensors.len(), 16);
        assert_eq!((laser.sensors.len(), laser.sensors[0].samples), (1, 180));
        assert!((laser.sensors[0].fov - PI).abs() < 1e-9);
        assert_eq!(laser.sensors[0].range, (0.0, 8.0));
        let r0 = &w.models[w.names["r0"]];
        assert_eq!((r0.size[0], r0.size[1]), (0.44, 0.38));
        let cave = &w.models[w.names["cave"]];
        assert!(!cave.obstacle_return && cave.ranger_return == 0.5 && cave.blocks.len() > 100);
    }
}
