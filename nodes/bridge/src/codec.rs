//! Player's XDR bodies ↔ Troupe's messages, interface by interface.
//!
//! Layouts follow Player 3's `libplayerinterface/interfaces/*.def` as
//! `playerxdrgen` encodes them (see [`crate::xdr`]). Three directions:
//!
//! - [`to_player`]: a device's data sample → a Player DATA subtype and body;
//! - [`from_player`]: a client's CMD or REQ → a Troupe command or request,
//!   with the function that turns the request's reply into Player's ACK body;
//! - `None` from either: Player defines the message, Troupe does not serve it
//!   (a REQ gets an empty NACK, as Player's drivers answer what they ignore).
//!
//! And the other way round, for `troupe bridge --import`, where Troupe is
//! the client of a Player server:
//!
//! - [`data_from_player`]: a server's DATA → a Troupe data sample;
//! - [`command_to_player`]: a Troupe command → a Player CMD subtype and body.

use std::io::Write;

use troupe_msgs::codec::{decode, encode, Command, Message, Request};
use troupe_msgs::protocol::{self as p, CMD, REQ};
use troupe_msgs::{
    aio, bumper, common, dio, fiducial, gripper, ir, laser, localize, log, map, planner,
    position2d, ptz, ranger, simulation, sonar, AnyMsg, Color, DecodeError, Interface, Pose2d,
    Pose3d, Size2d, Size3d,
};

use crate::xdr::{Reader, Writer, XdrError};

/// Why a message could not be translated.
#[derive(Debug, thiserror::Error)]
pub enum CodecError {
    /// A client's body does not match Player's layout for its subtype.
    #[error("{interface} {kind} subtype {subtype}: {source}")]
    Body {
        /// Interface name.
        interface: &'static str,
        /// `CMD` or `REQ`.
        kind: &'static str,
        /// Subtype.
        subtype: u8,
        /// What was wrong.
        source: XdrError,
    },
    /// A device answered with something else than the request's reply type.
    #[error("reply: {0}")]
    Reply(#[from] DecodeError),
}

/// Turns a Troupe reply payload into Player's ACK body.
pub type ReplyFn = Box<dyn Fn(&[u8]) -> Result<Vec<u8>, DecodeError> + Send + Sync>;

/// What a client's CMD or REQ becomes on Troupe's keys.
pub enum ToDevice {
    /// A put on `…/cmd/<name>`.
    Command {
        /// Key chunk.
        name: &'static str,
        /// Encoded Troupe command.
        payload: Vec<u8>,
    },
    /// A get on `…/req/<name>`; `reply` makes the ACK body.
    Request {
        /// Key chunk.
        name: &'static str,
        /// Encoded Troupe request.
        payload: Vec<u8>,
        /// ACK body from the reply.
        reply: ReplyFn,
    },
    /// A request Player's driver refuses for its form alone (a property
    /// asked with a buffer of the wrong size): NACKed here, with the reason
    /// in the bridge's log, as the driver logged it.
    Refuse(String),
}

impl std::fmt::Debug for ToDevice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ToDevice::Command { name, .. } => write!(f, "Command({name})"),
            ToDevice::Request { name, .. } => write!(f, "Request({name})"),
            ToDevice::Refuse(why) => write!(f, "Refuse({why})"),
        }
    }
}

fn command<C: Command>(c: &C, stamp: f64) -> ToDevice {
    ToDevice::Command {
        name: C::NAME,
        payload: encode(c, stamp),
    }
}

fn request<Q: Request>(
    q: &Q,
    stamp: f64,
    reply: impl Fn(&Q::Reply, &mut Writer) + Send + Sync + 'static,
) -> ToDevice
where
    Q::Reply: Message,
{
    ToDevice::Request {
        name: Q::NAME,
        payload: encode(q, stamp),
        reply: Box::new(move |p| {
            let r = decode::<Q::Reply>(p)?;
            let mut w = Writer::new();
            reply(&r.msg, &mut w);
            Ok(w.finish())
        }),
    }
}

/// The ACK body of a request Player answers with no body.
fn empty(_: &common::Ack, _: &mut Writer) {}

// ---- shared types ---------------------------------------------------------

fn w_pose2d(w: &mut Writer, p: &Pose2d) {
    w.f64(p.x).f64(p.y).f64(p.yaw);
}

fn w_pose3d(w: &mut Writer, p: &Pose3d) {
    w.f64(p.x)
        .f64(p.y)
        .f64(p.z)
        .f64(p.roll)
        .f64(p.pitch)
        .f64(p.yaw);
}

fn w_bbox3d(w: &mut Writer, s: &Size3d) {
    w.f64(s.width).f64(s.length).f64(s.height);
}

fn w_bbox2d(w: &mut Writer, s: &Size2d) {
    w.f64(s.width).f64(s.length);
}

fn r_pose2d(r: &mut Reader) -> Result<Pose2d, XdrError> {
    Ok(Pose2d::new(r.f64()?, r.f64()?, r.f64()?))
}

fn w_f32s(w: &mut Writer, v: &[f32]) {
    w.array(v, |w, x| {
        w.f32(*x);
    });
}

fn w_f64s(w: &mut Writer, v: &[f64]) {
    w.array(v, |w, x| {
        w.f64(*x);
    });
}

fn w_pose3ds(w: &mut Writer, v: &[Pose3d]) {
    w.array(v, w_pose3d);
}

// ---- device → client ------------------------------------------------------

/// A device's data sample as Player DATA: the interface it belongs to, its
/// subtype and body. `None` for Troupe messages Player has no DATA for.
pub fn to_player(msg: &AnyMsg) -> Option<(Interface, u8, Vec<u8>)> {
    use Interface as I;
    let mut w = Writer::new();
    let (iface, subtype) = match msg {
        AnyMsg::Position2dData(d) => {
            w_pose2d(&mut w, &d.pose);
            w_pose2d(&mut w, &d.vel);
            w.flag(d.stall);
            (I::Position2d, p::position2d::DATA_STATE)
        }
        AnyMsg::Position2dGeom(g) => {
            position2d_geom(g, &mut w);
            (I::Position2d, p::position2d::DATA_GEOM)
        }
        AnyMsg::LaserScan(s) => {
            laser_scan(s, &mut w);
            (I::Laser, p::laser::DATA_SCAN)
        }
        AnyMsg::LaserScanPose(s) => {
            laser_scan(&s.scan, &mut w);
            w_pose2d(&mut w, &s.pose);
            (I::Laser, p::laser::DATA_SCANPOSE)
        }
        AnyMsg::RangerRanges(r) => {
            w_f64s(&mut w, &r.ranges);
            (I::Ranger, p::ranger::DATA_RANGE)
        }
        AnyMsg::RangerIntensities(r) => {
            w_f64s(&mut w, &r.intensities);
            (I::Ranger, p::ranger::DATA_INTNS)
        }
        AnyMsg::RangerGeom(g) => {
            ranger_geom(g, &mut w);
            (I::Ranger, p::ranger::DATA_GEOM)
        }
        AnyMsg::SonarRanges(s) => {
            w_f32s(&mut w, &s.ranges);
            (I::Sonar, p::sonar::DATA_RANGES)
        }
        AnyMsg::SonarGeom(g) => {
            w_pose3ds(&mut w, &g.poses);
            (I::Sonar, p::sonar::DATA_GEOM)
        }
        AnyMsg::MapInfo(i) => {
            map_info(i, &mut w);
            (I::Map, p::map::DATA_INFO)
        }
        AnyMsg::LocalizeHypoths(h) => {
            w.u32(h.pending_count).f64(h.pending_time);
            w.array(&h.hypoths, |w, h| {
                w_pose2d(w, &h.mean);
                for c in h.cov {
                    w.f64(c);
                }
                w.f64(h.weight);
            });
            (I::Localize, p::localize::DATA_HYPOTHS)
        }
        AnyMsg::PlannerState(s) => {
            w.flag(s.valid).flag(s.done);
            w_pose2d(&mut w, &s.pose);
            w_pose2d(&mut w, &s.goal);
            w_pose2d(&mut w, &s.waypoint);
            w.i32(s.waypoint_idx).u32(s.waypoints_count);
            (I::Planner, p::planner::DATA_STATE)
        }
        AnyMsg::BlobfinderData(d) => {
            w.u32(d.width).u32(d.height);
            w.array(&d.blobs, |w, b| {
                w.u32(b.id)
                    .u32(b.color)
                    .u32(b.area)
                    .u32(b.x)
                    .u32(b.y)
                    .u32(b.left)
                    .u32(b.right)
                    .u32(b.top)
                    .u32(b.bottom)
                    .f32(b.range);
            });
            (I::Blobfinder, p::blobfinder::DATA_BLOBS)
        }
        AnyMsg::GripperData(d) => {
            let state = match d.state {
                gripper::State::Open => 1,
                gripper::State::Closed => 2,
                gripper::State::Moving => 3,
                gripper::State::Error => 4,
            };
            w.u32(state).u32(d.beams).u32(u32::from(d.stored));
            (I::Gripper, p::gripper::DATA_STATE)
        }
        AnyMsg::FiducialData(d) => {
            w.array(&d.fiducials, |w, f| {
                w.i32(f.id);
                w_pose3d(w, &f.pose);
                w_pose3d(w, &f.upose);
            });
            (I::Fiducial, p::fiducial::DATA_SCAN)
        }
        AnyMsg::PowerData(p) => {
            w.u32(p.valid)
                .f32(p.volts)
                .f32(p.percent)
                .f32(p.joules)
                .f32(p.watts)
                .i32(i32::from(p.charging));
            (I::Power, p::power::DATA_STATE)
        }
        AnyMsg::GpsData(g) => {
            // player_gps_data_t: Player's fixed-point fields.
            let fixed = |v: f64| v.round().clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32;
            let whole = |v: f64| v.round().clamp(0.0, f64::from(u32::MAX)) as u32;
            let secs = g.time.max(0.0).floor();
            w.u32(whole(secs))
                .u32(whole((g.time.max(0.0) - secs) * 1e6).min(999_999))
                .i32(fixed(g.latitude * 1e7))
                .i32(fixed(g.longitude * 1e7))
                .i32(fixed(g.altitude * 1e3))
                .f64(g.speed)
                .f64(g.course)
                .f64(g.utm_e)
                .f64(g.utm_n)
                .u32(g.quality)
                .u32(g.num_sats)
                .u32(whole(g.hdop * 10.0))
                .u32(whole(g.vdop * 10.0))
                .f64(g.err_horz)
                .f64(g.err_vert);
            (I::Gps, p::gps::DATA_STATE)
        }
        AnyMsg::CameraData(c) => {
            w.u32(c.width)
                .u32(c.height)
                .u32(c.bpp)
                .u32(c.format)
                .u32(c.fdiv)
                .u32(c.compression)
                .bytes(&c.image);
            (I::Camera, p::camera::DATA_STATE)
        }
        AnyMsg::WsnData(d) => {
            let p = &d.readings;
            w.u32(d.node_type).u32(d.node_id).u32(d.node_parent_id);
            for v in [
                p.light,
                p.mic,
                p.accel_x,
                p.accel_y,
                p.accel_z,
                p.magn_x,
                p.magn_y,
                p.magn_z,
                p.temperature,
                p.battery,
            ] {
                w.f32(v);
            }
            (I::Wsn, p::wsn::DATA_STATE)
        }
        AnyMsg::BumperData(b) => {
            let bits: Vec<u8> = b.bumpers.iter().map(|&x| u8::from(x)).collect();
            w.bytes(&bits);
            (I::Bumper, p::bumper::DATA_STATE)
        }
        AnyMsg::BumperGeom(g) => {
            bumper_geom(g, &mut w);
            (I::Bumper, p::bumper::DATA_GEOM)
        }
        AnyMsg::IrData(d) => {
            w_f32s(&mut w, &d.voltages);
            w_f32s(&mut w, &d.ranges);
            (I::Ir, p::ir::DATA_RANGES)
        }
        AnyMsg::AioData(d) => {
            w_f32s(&mut w, &d.voltages);
            (I::Aio, p::aio::DATA_STATE)
        }
        AnyMsg::DioData(d) => {
            w.u32(d.count).u32(d.bits);
            (I::Dio, p::dio::DATA_VALUES)
        }
        AnyMsg::PtzData(d) => {
            w.f32(d.pan)
                .f32(d.tilt)
                .f32(d.zoom)
                .f32(d.panspeed)
                .f32(d.tiltspeed)
                .u32(0);
            (I::Ptz, p::ptz::DATA_STATE)
        }
        _ => return None,
    };
    Some((iface, subtype, w.finish()))
}

fn position2d_geom(g: &position2d::Geom, w: &mut Writer) {
    w_pose3d(w, &g.pose);
    w_bbox3d(w, &g.size);
}

fn laser_scan(s: &laser::Scan, w: &mut Writer) {
    w.f32(s.min_angle)
        .f32(s.max_angle)
        .f32(s.resolution)
        .f32(s.max_range);
    w_f32s(w, &s.ranges);
    w.bytes(&s.intensity);
    w.u32(s.id);
}

fn laser_geom(g: &laser::Geom, w: &mut Writer) {
    w_pose3d(w, &g.pose);
    w_bbox3d(w, &g.size);
}

fn laser_config(c: &laser::Config, w: &mut Writer) {
    w.f32(c.min_angle)
        .f32(c.max_angle)
        .f32(c.resolution)
        .f32(c.max_range)
        .f32(c.range_res)
        .flag(c.intensity)
        .f32(c.scanning_frequency);
}

fn ranger_geom(g: &ranger::Geom, w: &mut Writer) {
    w_pose3d(w, &g.pose);
    w_bbox3d(w, &g.size);
    w_pose3ds(w, &g.element_poses);
    w.array(&g.element_sizes, w_bbox3d);
}

fn ranger_config(c: &ranger::Config, w: &mut Writer) {
    w.f64(c.min_angle)
        .f64(c.max_angle)
        .f64(c.angular_res)
        .f64(c.min_range)
        .f64(c.max_range)
        .f64(c.range_res)
        .f64(c.frequency);
}

fn map_info(i: &map::Info, w: &mut Writer) {
    w.f32(i.resolution).u32(i.width).u32(i.height);
    w_pose2d(w, &i.origin);
}

/// A map tile as Player 3 sends it: the cells zlib-compressed.
fn map_data(d: &map::Data, w: &mut Writer) {
    // Cells are int8; the wire carries their two's-complement bytes.
    let raw: Vec<u8> = d.cells.iter().map(|&c| c as u8).collect();
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
    // Writing into a Vec cannot fail.
    let zipped = z
        .write_all(&raw)
        .and_then(|()| z.finish())
        .unwrap_or_default();
    w.u32(d.col).u32(d.row).u32(d.width).u32(d.height);
    // data_count, data_range (the largest cell value), then xdr_bytes.
    w.u32(u32::try_from(zipped.len()).unwrap_or(u32::MAX))
        .i32(1)
        .xdr_bytes(&zipped);
}

fn bumper_geom(g: &bumper::Geom, w: &mut Writer) {
    w.array(&g.bumpers, |w, b| {
        w_pose3d(w, &b.pose);
        w.f32(b.length).f32(b.radius);
    });
}

/// Stage's property values are raw host-order bytes (colour = 4 LE floats).
/// A property's value in the client's buffer of `size` bytes, as Stage's
/// plugin copies it: in the server's (little-endian) byte order, an
/// integer as wide as the buffer holds.
fn property_bytes(v: &simulation::Value, size: usize) -> Vec<u8> {
    match v {
        simulation::Value::Color(c) => [c.r, c.g, c.b, c.a]
            .iter()
            .flat_map(|x| x.to_le_bytes())
            .collect(),
        simulation::Value::Number(x) => x.to_le_bytes().to_vec(),
        simulation::Value::Int(i) => match i32::try_from(*i) {
            Ok(i) if size == 4 => i.to_le_bytes().to_vec(),
            _ => i.to_le_bytes().to_vec(),
        },
        simulation::Value::Text(s) => {
            let mut b = s.as_bytes().to_vec();
            b.push(0);
            b
        }
    }
}

fn property_value(prop: &str, b: &[u8]) -> simulation::Value {
    let f32_at = |i: usize| f32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
    match b.len() {
        16 if prop.starts_with("colo") => simulation::Value::Color(Color {
            r: f32_at(0),
            g: f32_at(4),
            b: f32_at(8),
            a: f32_at(12),
        }),
        8 => {
            let mut x = [0; 8];
            x.copy_from_slice(b);
            simulation::Value::Number(f64::from_le_bytes(x))
        }
        4 => simulation::Value::Int(i64::from(i32::from_le_bytes([b[0], b[1], b[2], b[3]]))),
        _ => {
            let end = b.iter().position(|&c| c == 0).unwrap_or(b.len());
            simulation::Value::Text(String::from_utf8_lossy(&b[..end]).into_owned())
        }
    }
}

// ---- client → device ------------------------------------------------------

/// A client's CMD or REQ to a device of `iface` as a Troupe command or
/// request. `Ok(None)`: Player defines it, Troupe does not serve it.
///
/// # Errors
///
/// [`CodecError::Body`] when the body does not match Player's layout.
pub fn from_player(
    iface: Interface,
    kind: u8,
    subtype: u8,
    body: &[u8],
    stamp: f64,
) -> Result<Option<ToDevice>, CodecError> {
    let mut r = Reader::new(body);
    // A message Troupe does not serve is refused whatever its body holds.
    let out = translate(iface, kind, subtype, &mut r, stamp).and_then(|out| {
        if out.is_some() {
            r.end()?;
        }
        Ok(out)
    });
    out.map_err(|source| CodecError::Body {
        interface: iface.name(),
        kind: if kind == CMD { "CMD" } else { "REQ" },
        subtype,
        source,
    })
}

fn translate(
    iface: Interface,
    kind: u8,
    subtype: u8,
    r: &mut Reader,
    t: f64,
) -> Result<Option<ToDevice>, XdrError> {
    use Interface as I;
    let out = match (iface, kind, subtype) {
        // position2d
        (I::Position2d, CMD, p::position2d::CMD_VEL) => command(
            &position2d::CmdVel {
                vel: r_pose2d(r)?,
                state: r.flag()?,
            },
            t,
        ),
        (I::Position2d, CMD, p::position2d::CMD_POS) => command(
            &position2d::CmdPos {
                pos: r_pose2d(r)?,
                vel: r_pose2d(r)?,
                state: r.flag()?,
            },
            t,
        ),
        (I::Position2d, CMD, p::position2d::CMD_CAR) => command(
            &position2d::CmdCar {
                velocity: r.f64()?,
                angle: r.f64()?,
            },
            t,
        ),
        (I::Position2d, REQ, p::position2d::REQ_GET_GEOM) => {
            request(&position2d::GetGeom, t, position2d_geom)
        }
        (I::Position2d, REQ, p::position2d::REQ_MOTOR_POWER) => {
            request(&position2d::MotorPower { state: r.flag()? }, t, empty)
        }
        (I::Position2d, REQ, p::position2d::REQ_VELOCITY_MODE) => {
            request(&position2d::VelocityMode { value: r.u32()? }, t, empty)
        }
        (I::Position2d, REQ, p::position2d::REQ_POSITION_MODE) => {
            request(&position2d::PositionMode { state: r.flag()? }, t, empty)
        }
        (I::Position2d, REQ, p::position2d::REQ_SET_ODOM) => {
            request(&position2d::SetOdom { pose: r_pose2d(r)? }, t, empty)
        }
        (I::Position2d, REQ, p::position2d::REQ_RESET_ODOM) => {
            request(&position2d::ResetOdom, t, empty)
        }

        // log
        (I::Log, REQ, p::log::REQ_SET_WRITE_STATE) => {
            request(&log::SetWriteState { state: r.flag()? }, t, empty)
        }
        (I::Log, REQ, p::log::REQ_SET_READ_STATE) => {
            request(&log::SetReadState { state: r.flag()? }, t, empty)
        }
        (I::Log, REQ, p::log::REQ_GET_STATE) => request(&log::GetState, t, |s, w| {
            w.u32(u32::from(s.kind)).flag(s.state);
        }),
        (I::Log, REQ, p::log::REQ_SET_READ_REWIND) => request(&log::Rewind, t, empty),
        (I::Log, REQ, p::log::REQ_SET_FILENAME) => request(
            &log::SetFilename {
                filename: r.string()?,
            },
            t,
            empty,
        ),

        // laser
        (I::Laser, REQ, p::laser::REQ_GET_GEOM) => request(&laser::GetGeom, t, laser_geom),
        (I::Laser, REQ, p::laser::REQ_SET_CONFIG) => {
            let config = laser::Config {
                min_angle: r.f32()?,
                max_angle: r.f32()?,
                resolution: r.f32()?,
                max_range: r.f32()?,
                range_res: r.f32()?,
                intensity: r.flag()?,
                scanning_frequency: r.f32()?,
            };
            request(&laser::SetConfig { config }, t, laser_config)
        }
        (I::Laser, REQ, p::laser::REQ_GET_CONFIG) => request(&laser::GetConfig, t, laser_config),
        (I::Laser, REQ, p::laser::REQ_GET_ID) => request(&laser::GetId, t, |i, w| {
            w.u32(i.serial_number);
        }),
        (I::Laser | I::Ranger | I::Sonar, REQ, _) if is_power(iface, subtype) => {
            request(&common::Power { state: r.flag()? }, t, empty)
        }

        // ranger
        (I::Ranger, REQ, p::ranger::REQ_GET_GEOM) => request(&ranger::GetGeom, t, ranger_geom),
        (I::Ranger, REQ, p::ranger::REQ_INTNS) => {
            request(&ranger::IntensityEnable { state: r.flag()? }, t, empty)
        }
        (I::Ranger, REQ, p::ranger::REQ_SET_CONFIG) => {
            let config = ranger::Config {
                min_angle: r.f64()?,
                max_angle: r.f64()?,
                angular_res: r.f64()?,
                min_range: r.f64()?,
                max_range: r.f64()?,
                range_res: r.f64()?,
                frequency: r.f64()?,
            };
            request(&ranger::SetConfig { config }, t, ranger_config)
        }
        (I::Ranger, REQ, p::ranger::REQ_GET_CONFIG) => {
            request(&ranger::GetConfig, t, ranger_config)
        }

        // sonar
        (I::Sonar, REQ, p::sonar::REQ_GET_GEOM) => {
            request(&sonar::GetGeom, t, |g, w| w_pose3ds(w, &g.poses))
        }

        // map
        (I::Map, REQ, p::map::REQ_GET_INFO) => request(&map::GetInfo, t, map_info),
        (I::Map, REQ, p::map::REQ_GET_DATA) => {
            let q = map::GetData {
                col: r.u32()?,
                row: r.u32()?,
                width: r.u32()?,
                height: r.u32()?,
            };
            let _data_count = r.u32()?;
            let _data_range = r.i32()?;
            let _data = r.xdr_bytes()?;
            request(&q, t, map_data)
        }
        (I::Map, REQ, p::map::REQ_GET_VECTOR) => request(&map::GetVector, t, |v, w| {
            w.f32(v.min_x as f32)
                .f32(v.max_x as f32)
                .f32(v.min_y as f32)
                .f32(v.max_y as f32);
            w.array(&v.segments, |w, s| {
                w.f64(s.x0).f64(s.y0).f64(s.x1).f64(s.y1);
            });
        }),

        // localize
        (I::Localize, REQ, p::localize::REQ_SET_POSE) => {
            let mean = r_pose2d(r)?;
            let mut cov = [0.0; 6];
            for c in &mut cov {
                *c = r.f64()?;
            }
            let q = localize::SetPose { mean, cov };
            request(&q, t, empty)
        }
        (I::Localize, REQ, p::localize::REQ_GET_PARTICLES) => {
            request(&localize::GetParticles, t, |p, w| {
                w_pose2d(w, &p.mean);
                w.f64(p.variance);
                w.array(&p.particles, |w, p| {
                    w_pose2d(w, &p.pose);
                    w.f64(p.weight);
                });
            })
        }

        // planner
        (I::Planner, CMD, p::planner::CMD_GOAL) => {
            command(&planner::Goal { goal: r_pose2d(r)? }, t)
        }
        (I::Planner, REQ, p::planner::REQ_GET_WAYPOINTS) => {
            request(&planner::GetWaypoints, t, |p, w| {
                let dist: f64 = p
                    .waypoints
                    .windows(2)
                    .map(|ab| (ab[1].x - ab[0].x).hypot(ab[1].y - ab[0].y))
                    .sum();
                w.f64(dist);
                w.array(&p.waypoints, w_pose2d);
            })
        }
        (I::Planner, REQ, p::planner::REQ_ENABLE) => {
            request(&planner::Enable { state: r.flag()? }, t, empty)
        }

        // simulation
        (I::Simulation, REQ, p::simulation::REQ_GET_POSE2D) => {
            let name = r.string()?;
            let _pose = r_pose2d(r)?; // libplayerc sends its buffer's garbage here
            request(&simulation::GetPose2d { name }, t, |p, w| {
                w.string(&p.name);
                w_pose2d(w, &p.pose);
            })
        }
        (I::Simulation, REQ, p::simulation::REQ_SET_POSE2D) => {
            let q = simulation::SetPose2d {
                name: r.string()?,
                pose: r_pose2d(r)?,
            };
            request(&q, t, empty)
        }
        (I::Simulation, REQ, p::simulation::REQ_GET_POSE3D) => {
            let name = r.string()?;
            let _pose = r_pose3d(r)?; // the client's buffer, as for GET_POSE2D
            let _simtime = r.f64()?;
            request(&simulation::GetPose3d { name }, t, |p, w| {
                w.string(&p.name);
                w_pose3d(w, &p.pose);
                w.f64(p.simtime);
            })
        }
        (I::Simulation, REQ, p::simulation::REQ_SET_POSE3D) => {
            let q = simulation::SetPose3d {
                name: r.string()?,
                pose: r_pose3d(r)?,
            };
            let _simtime = r.f64()?;
            request(&q, t, empty)
        }
        (I::Simulation, REQ, p::simulation::REQ_GET_PROPERTY) => {
            let name = r.string()?;
            let prop = r.string()?;
            let _index = r.u32()?;
            let buffer = r.bytes()?.len();
            // Stage's plugin refuses a buffer that cannot hold the value:
            // a colour is four floats, the time a uint64 of microseconds.
            let needs = match prop.as_str() {
                "color" => Some((16, "an array of 4 floats")),
                "time" => Some((8, "a uint64_t")),
                _ => None,
            };
            if let Some((size, what)) = needs.filter(|(size, _)| *size != buffer) {
                return Ok(Some(ToDevice::Refuse(format!(
                    "property \"{prop}\" of \"{name}\" needs {what} ({size} bytes) to store; the request brings {buffer}"
                ))));
            }
            request(&simulation::GetProperty { name, prop }, t, move |p, w| {
                w.string(&p.name).string(&p.prop).u32(0);
                w.bytes(&property_bytes(&p.value, buffer));
            })
        }
        (I::Simulation, REQ, p::simulation::REQ_SET_PROPERTY) => {
            let name = r.string()?;
            let prop = r.string()?;
            let _index = r.u32()?;
            let value = property_value(&prop, r.bytes()?);
            request(&simulation::SetProperty { name, prop, value }, t, empty)
        }

        // gripper
        (I::Gripper, CMD, p::gripper::CMD_OPEN) => command(&gripper::Open, t),
        (I::Gripper, CMD, p::gripper::CMD_CLOSE) => command(&gripper::Close, t),
        (I::Gripper, CMD, p::gripper::CMD_STOP) => command(&gripper::Stop, t),
        (I::Gripper, REQ, p::gripper::REQ_GET_GEOM) => request(&gripper::GetGeom, t, |g, w| {
            w_pose3d(w, &g.pose);
            w_bbox3d(w, &g.outer_size);
            w_bbox3d(w, &g.inner_size);
            w.u32(u32::from(g.num_beams)).u32(u32::from(g.capacity));
        }),

        // fiducial
        (I::Fiducial, REQ, p::fiducial::REQ_GET_GEOM) => request(&fiducial::GetGeom, t, |g, w| {
            w_pose3d(w, &g.pose);
            w_bbox3d(w, &g.size);
            w_bbox2d(w, &g.fiducial_size);
        }),
        (I::Fiducial, REQ, p::fiducial::REQ_GET_ID) => request(&fiducial::GetId, t, |i, w| {
            w.u32(i.id);
        }),
        (I::Fiducial, REQ, p::fiducial::REQ_SET_ID) => {
            request(&fiducial::SetId { id: r.u32()? }, t, |i, w| {
                w.u32(i.id);
            })
        }

        // bumper, ir, aio, dio, ptz
        (I::Bumper, REQ, p::bumper::REQ_GET_GEOM) => request(&bumper::GetGeom, t, bumper_geom),
        (I::Ir, REQ, p::ir::REQ_POSE) => request(&ir::GetGeom, t, |g, w| w_pose3ds(w, &g.poses)),
        (I::Ir, REQ, p::ir::REQ_POWER) => request(&common::Power { state: r.flag()? }, t, empty),
        (I::Aio, CMD, p::aio::CMD_STATE) => command(
            &aio::Cmd {
                id: r.u32()?,
                voltage: r.f32()?,
            },
            t,
        ),
        (I::Dio, CMD, p::dio::CMD_VALUES) => command(
            &dio::Cmd {
                count: r.u32()?,
                bits: r.u32()?,
            },
            t,
        ),
        (I::Ptz, CMD, p::ptz::CMD_STATE) => command(
            &ptz::Cmd {
                target: ptz::Data {
                    pan: r.f32()?,
                    tilt: r.f32()?,
                    zoom: r.f32()?,
                    panspeed: r.f32()?,
                    tiltspeed: r.f32()?,
                },
            },
            t,
        ),
        _ => return Ok(None),
    };
    Ok(Some(out))
}

// ---- server → Troupe (import) ---------------------------------------------

fn r_f32s(r: &mut Reader) -> Result<Vec<f32>, XdrError> {
    r.array(4, |r| r.f32())
}

fn r_f64s(r: &mut Reader) -> Result<Vec<f64>, XdrError> {
    r.array(8, |r| r.f64())
}

fn r_laser_scan(r: &mut Reader) -> Result<laser::Scan, XdrError> {
    Ok(laser::Scan {
        min_angle: r.f32()?,
        max_angle: r.f32()?,
        resolution: r.f32()?,
        max_range: r.f32()?,
        ranges: r_f32s(r)?,
        intensity: r.bytes()?.to_vec(),
        id: r.u32()?,
    })
}

/// A Player server's DATA message of `iface` as a Troupe sample stamped
/// `stamp`, ready to publish on the device's data key. `Ok(None)`: a DATA
/// subtype Troupe does not import.
///
/// # Errors
///
/// [`CodecError::Body`] when the body does not match Player's layout.
pub fn data_from_player(
    iface: Interface,
    subtype: u8,
    body: &[u8],
    stamp: f64,
) -> Result<Option<Vec<u8>>, CodecError> {
    use Interface as I;
    let mut r = Reader::new(body);
    let r = &mut r;
    let out = (|| -> Result<Option<Vec<u8>>, XdrError> {
        let payload = match (iface, subtype) {
            (I::Position2d, p::position2d::DATA_STATE) => encode(
                &position2d::Data {
                    pose: r_pose2d(r)?,
                    vel: r_pose2d(r)?,
                    stall: r.flag()?,
                },
                stamp,
            ),
            (I::Laser, p::laser::DATA_SCAN) => encode(&r_laser_scan(r)?, stamp),
            (I::Laser, p::laser::DATA_SCANPOSE) => encode(
                &laser::ScanPose {
                    scan: r_laser_scan(r)?,
                    pose: r_pose2d(r)?,
                },
                stamp,
            ),
            (I::Ranger, p::ranger::DATA_RANGE) => {
                encode(&ranger::Ranges { ranges: r_f64s(r)? }, stamp)
            }
            (I::Ranger, p::ranger::DATA_INTNS) => encode(
                &ranger::Intensities {
                    intensities: r_f64s(r)?,
                },
                stamp,
            ),
            (I::Sonar, p::sonar::DATA_RANGES) => {
                encode(&sonar::Ranges { ranges: r_f32s(r)? }, stamp)
            }
            (I::Power, p::power::DATA_STATE) => encode(
                &troupe_msgs::power::Data {
                    valid: r.u32()?,
                    volts: r.f32()?,
                    percent: r.f32()?,
                    joules: r.f32()?,
                    watts: r.f32()?,
                    charging: r.i32()? != 0,
                },
                stamp,
            ),
            (I::Gps, p::gps::DATA_STATE) => {
                let (secs, usecs) = (r.u32()?, r.u32()?);
                encode(
                    &troupe_msgs::gps::Data {
                        time: f64::from(secs) + f64::from(usecs) * 1e-6,
                        latitude: f64::from(r.i32()?) / 1e7,
                        longitude: f64::from(r.i32()?) / 1e7,
                        altitude: f64::from(r.i32()?) / 1e3,
                        speed: r.f64()?,
                        course: r.f64()?,
                        utm_e: r.f64()?,
                        utm_n: r.f64()?,
                        quality: r.u32()?,
                        num_sats: r.u32()?,
                        hdop: f64::from(r.u32()?) / 10.0,
                        vdop: f64::from(r.u32()?) / 10.0,
                        err_horz: r.f64()?,
                        err_vert: r.f64()?,
                    },
                    stamp,
                )
            }
            (I::Camera, p::camera::DATA_STATE) => encode(
                &troupe_msgs::camera::Data {
                    width: r.u32()?,
                    height: r.u32()?,
                    bpp: r.u32()?,
                    format: r.u32()?,
                    fdiv: r.u32()?,
                    compression: r.u32()?,
                    image: r.bytes()?.to_vec(),
                },
                stamp,
            ),
            (I::Wsn, p::wsn::DATA_STATE) => encode(
                &troupe_msgs::wsn::Data {
                    node_type: r.u32()?,
                    node_id: r.u32()?,
                    node_parent_id: r.u32()?,
                    readings: troupe_msgs::wsn::Readings {
                        light: r.f32()?,
                        mic: r.f32()?,
                        accel_x: r.f32()?,
                        accel_y: r.f32()?,
                        accel_z: r.f32()?,
                        magn_x: r.f32()?,
                        magn_y: r.f32()?,
                        magn_z: r.f32()?,
                        temperature: r.f32()?,
                        battery: r.f32()?,
                    },
                },
                stamp,
            ),
            (I::Ir, p::ir::DATA_RANGES) => encode(
                &ir::Data {
                    voltages: r_f32s(r)?,
                    ranges: r_f32s(r)?,
                },
                stamp,
            ),
            (I::Aio, p::aio::DATA_STATE) => encode(
                &aio::Data {
                    voltages: r_f32s(r)?,
                },
                stamp,
            ),
            (I::Dio, p::dio::DATA_VALUES) => encode(
                &dio::Data {
                    count: r.u32()?,
                    bits: r.u32()?,
                },
                stamp,
            ),
            _ => return Ok(None),
        };
        r.end()?;
        Ok(Some(payload))
    })();
    out.map_err(|source| CodecError::Body {
        interface: iface.name(),
        kind: "DATA",
        subtype,
        source,
    })
}

/// A Troupe command (an encoded payload) as the Player CMD that carries it
/// to a device of a Player server: `(subtype, body)`. `None` for a command
/// Player's interface has no CMD for, or a payload that is not a command.
pub fn command_to_player(payload: &[u8]) -> Option<(u8, Vec<u8>)> {
    let msg = troupe_msgs::decode_any(payload).ok()?.msg;
    let mut w = Writer::new();
    let subtype = match &msg {
        AnyMsg::Position2dCmdVel(c) => {
            w_pose2d(&mut w, &c.vel);
            w.flag(c.state);
            1
        }
        AnyMsg::Position2dCmdPos(c) => {
            w_pose2d(&mut w, &c.pos);
            w_pose2d(&mut w, &c.vel);
            w.flag(c.state);
            2
        }
        AnyMsg::Position2dCmdCar(c) => {
            w.f64(c.velocity).f64(c.angle);
            3
        }
        AnyMsg::PlannerGoal(g) => {
            w_pose2d(&mut w, &g.goal);
            1
        }
        AnyMsg::GripperOpen(_) => 1,
        AnyMsg::GripperClose(_) => 2,
        AnyMsg::GripperStop(_) => 3,
        AnyMsg::AioCmd(c) => {
            w.u32(c.id).f32(c.voltage);
            1
        }
        AnyMsg::DioCmd(c) => {
            w.u32(c.count).u32(c.bits);
            1
        }
        AnyMsg::PtzCmd(c) => {
            let t = &c.target;
            w.f32(t.pan)
                .f32(t.tilt)
                .f32(t.zoom)
                .f32(t.panspeed)
                .f32(t.tiltspeed);
            1
        }
        _ => return None,
    };
    Some((subtype, w.finish()))
}

fn r_pose3d(r: &mut Reader) -> Result<Pose3d, XdrError> {
    Ok(Pose3d {
        x: r.f64()?,
        y: r.f64()?,
        z: r.f64()?,
        roll: r.f64()?,
        pitch: r.f64()?,
        yaw: r.f64()?,
    })
}

fn r_bbox3d(r: &mut Reader) -> Result<Size3d, XdrError> {
    Ok(Size3d {
        width: r.f64()?,
        length: r.f64()?,
        height: r.f64()?,
    })
}

/// Turns a Player server's ACK body into the Troupe reply, stamped.
pub type ReplyFromServer = Box<dyn Fn(&[u8], f64) -> Result<Vec<u8>, XdrError> + Send + Sync>;

/// A Troupe request as the Player REQ that asks a server for it.
pub struct ToServer {
    /// The REQ subtype.
    pub subtype: u8,
    /// Its body.
    pub body: Vec<u8>,
    /// What makes the Troupe reply from the server's ACK body.
    pub reply: ReplyFromServer,
}

fn answer<M: Message + 'static>(read: fn(&mut Reader) -> Result<M, XdrError>) -> ReplyFromServer {
    Box::new(move |b, t| {
        let mut r = Reader::new(b);
        let m = read(&mut r)?;
        r.end()?;
        Ok(encode(&m, t))
    })
}

/// Player's drivers answer these with an empty ACK (some echo the request;
/// the body is not read).
fn acked() -> ReplyFromServer {
    Box::new(|_, t| Ok(encode(&common::Ack, t)))
}

fn r_laser_config(r: &mut Reader) -> Result<laser::Config, XdrError> {
    Ok(laser::Config {
        min_angle: r.f32()?,
        max_angle: r.f32()?,
        resolution: r.f32()?,
        max_range: r.f32()?,
        range_res: r.f32()?,
        intensity: r.flag()?,
        scanning_frequency: r.f32()?,
    })
}

fn r_ranger_config(r: &mut Reader) -> Result<ranger::Config, XdrError> {
    Ok(ranger::Config {
        min_angle: r.f64()?,
        max_angle: r.f64()?,
        angular_res: r.f64()?,
        min_range: r.f64()?,
        max_range: r.f64()?,
        range_res: r.f64()?,
        frequency: r.f64()?,
    })
}

/// A Troupe request (an encoded payload) to a device of `iface` as the REQ a
/// Player server answers, with the reading of its ACK. `None`: a request
/// Troupe does not forward to Player servers.
pub fn request_to_player(iface: Interface, payload: &[u8]) -> Option<ToServer> {
    let msg = troupe_msgs::decode_any(payload).ok()?.msg;
    let mut w = Writer::new();
    let (subtype, reply) = match &msg {
        AnyMsg::Position2dGetGeom(_) => (
            p::position2d::REQ_GET_GEOM,
            answer(|r| {
                Ok(position2d::Geom {
                    pose: r_pose3d(r)?,
                    size: r_bbox3d(r)?,
                })
            }),
        ),
        AnyMsg::Position2dMotorPower(q) => {
            w.flag(q.state);
            (p::position2d::REQ_MOTOR_POWER, acked())
        }
        AnyMsg::Position2dVelocityMode(q) => {
            w.u32(q.value);
            (p::position2d::REQ_VELOCITY_MODE, acked())
        }
        AnyMsg::Position2dPositionMode(q) => {
            w.flag(q.state);
            (p::position2d::REQ_POSITION_MODE, acked())
        }
        AnyMsg::Position2dSetOdom(q) => {
            w_pose2d(&mut w, &q.pose);
            (p::position2d::REQ_SET_ODOM, acked())
        }
        AnyMsg::Position2dResetOdom(_) => (p::position2d::REQ_RESET_ODOM, acked()),
        AnyMsg::LaserGetGeom(_) => (
            p::laser::REQ_GET_GEOM,
            answer(|r| {
                Ok(laser::Geom {
                    pose: r_pose3d(r)?,
                    size: r_bbox3d(r)?,
                })
            }),
        ),
        AnyMsg::LaserSetConfig(q) => {
            laser_config(&q.config, &mut w);
            (p::laser::REQ_SET_CONFIG, answer(r_laser_config))
        }
        AnyMsg::LaserGetConfig(_) => (p::laser::REQ_GET_CONFIG, answer(r_laser_config)),
        AnyMsg::RangerGetGeom(_) => (
            p::ranger::REQ_GET_GEOM,
            answer(|r| {
                Ok(ranger::Geom {
                    pose: r_pose3d(r)?,
                    size: r_bbox3d(r)?,
                    element_poses: r.array(48, r_pose3d)?,
                    element_sizes: r.array(24, r_bbox3d)?,
                })
            }),
        ),
        AnyMsg::RangerSetConfig(q) => {
            ranger_config(&q.config, &mut w);
            (p::ranger::REQ_SET_CONFIG, answer(r_ranger_config))
        }
        AnyMsg::RangerGetConfig(_) => (p::ranger::REQ_GET_CONFIG, answer(r_ranger_config)),
        AnyMsg::SonarGetGeom(_) => (
            p::sonar::REQ_GET_GEOM,
            answer(|r| {
                Ok(sonar::Geom {
                    poses: r.array(48, r_pose3d)?,
                })
            }),
        ),
        AnyMsg::MapGetInfo(_) => (
            p::map::REQ_GET_INFO,
            answer(|r| {
                Ok(map::Info {
                    resolution: r.f32()?,
                    width: r.u32()?,
                    height: r.u32()?,
                    origin: r_pose2d(r)?,
                })
            }),
        ),
        AnyMsg::PlannerEnable(q) => {
            w.flag(q.state);
            (p::planner::REQ_ENABLE, acked())
        }
        AnyMsg::LocalizeSetPose(q) => {
            w_pose2d(&mut w, &q.mean);
            for c in q.cov {
                w.f64(c);
            }
            (p::localize::REQ_SET_POSE, acked())
        }
        AnyMsg::Power(q) => {
            let subtype = match iface {
                Interface::Laser => p::laser::REQ_POWER,
                Interface::Ranger => p::ranger::REQ_POWER,
                Interface::Sonar => p::sonar::REQ_POWER,
                Interface::Ir => p::ir::REQ_POWER,
                _ => return None,
            };
            w.flag(q.state);
            (subtype, acked())
        }
        _ => return None,
    };
    Some(ToServer {
        subtype,
        body: w.finish(),
        reply,
    })
}

/// Player's POWER requests of the laser, ranger and sonar.
fn is_power(iface: Interface, subtype: u8) -> bool {
    matches!(
        (iface, subtype),
        (Interface::Laser, p::laser::REQ_POWER)
            | (Interface::Ranger, p::ranger::REQ_POWER)
            | (Interface::Sonar, p::sonar::REQ_POWER)
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What a server sends, read back: every DATA the bridge writes comes
    /// back as the message it was made from.
    #[test]
    fn imported_data_is_what_the_bridge_exported() {
        let samples = [
            AnyMsg::Position2dData(position2d::Data {
                pose: Pose2d::new(1.5, -2.0, 0.3),
                vel: Pose2d::new(0.2, 0.0, -0.1),
                stall: true,
            }),
            AnyMsg::LaserScan(laser::Scan {
                min_angle: -1.5,
                max_angle: 1.5,
                resolution: 0.5,
                max_range: 8.0,
                ranges: vec![1.0, 2.5, 8.0, 0.25, 3.0, 4.0, 5.0],
                intensity: vec![0, 1, 0, 0, 2, 0, 1],
                id: 41,
            }),
            AnyMsg::RangerRanges(ranger::Ranges {
                ranges: vec![0.5, 1.25, 5.0],
            }),
            AnyMsg::RangerIntensities(ranger::Intensities {
                intensities: vec![1.0, 0.0, 3.0],
            }),
            AnyMsg::SonarRanges(sonar::Ranges {
                ranges: vec![0.5, 1.5, 4.75],
            }),
            AnyMsg::PowerData(troupe_msgs::power::Data {
                valid: 1,
                volts: 12.5,
                percent: 80.0,
                joules: 0.0,
                watts: 0.0,
                charging: true,
            }),
            AnyMsg::IrData(ir::Data {
                voltages: vec![1.0, 2.0],
                ranges: vec![0.5, 0.25],
            }),
            AnyMsg::AioData(aio::Data {
                voltages: vec![3.25],
            }),
            AnyMsg::DioData(dio::Data {
                count: 8,
                bits: 0xA5,
            }),
            AnyMsg::GpsData(gps_fix()),
            AnyMsg::CameraData(troupe_msgs::camera::Data {
                width: 3,
                height: 1,
                bpp: 8,
                format: troupe_msgs::camera::FORMAT_MONO8,
                fdiv: 0,
                compression: troupe_msgs::camera::COMPRESS_RAW,
                image: vec![0, 128, 255],
            }),
            AnyMsg::WsnData(troupe_msgs::wsn::Data {
                node_type: 132,
                node_id: 1,
                node_parent_id: 125,
                readings: troupe_msgs::wsn::Readings {
                    light: 779.0,
                    battery: 489.0,
                    ..Default::default()
                },
            }),
        ];
        for m in samples {
            let (iface, subtype, body) = to_player(&m).unwrap();
            let payload = data_from_player(iface, subtype, &body, 12.5)
                .unwrap()
                .unwrap_or_else(|| panic!("{m:?} is not imported"));
            let back = troupe_msgs::decode_any(&payload).unwrap();
            assert_eq!(back.msg, m);
            assert_eq!(back.stamp, 12.5);
        }
        // A body of the wrong length is refused, naming the message.
        let (iface, subtype, body) = to_player(&AnyMsg::DioData(dio::Data::default())).unwrap();
        let e = data_from_player(iface, subtype, &body[..4], 0.0).unwrap_err();
        assert!(e.to_string().contains("dio DATA subtype 1"), "{e}");
        assert!(data_from_player(Interface::Map, 1, &[], 0.0)
            .unwrap()
            .is_none());
    }

    /// A fix whose values Player's fixed point carries exactly.
    fn gps_fix() -> troupe_msgs::gps::Data {
        troupe_msgs::gps::Data {
            time: 1_700_000_000.5,
            latitude: 43.5,
            longitude: -79.25,
            altitude: 76.125,
            speed: 1.25,
            course: 0.5,
            utm_e: 630_084.25,
            utm_n: 4_833_438.5,
            quality: 2,
            num_sats: 9,
            hdop: 1.5,
            vdop: 2.0,
            err_horz: 0.75,
            err_vert: 1.5,
        }
    }

    /// `player_gps_data_t` as Player's XDR packs it: seconds and
    /// microseconds, degrees times 1e7, millimetres, the dilutions times ten.
    #[test]
    fn gps_data_is_player_s_fixed_point() {
        let (iface, subtype, body) = to_player(&AnyMsg::GpsData(gps_fix())).unwrap();
        assert_eq!((iface, subtype), (Interface::Gps, 1));
        assert_eq!(body.len(), 84);
        let word = |at: usize| u32::from_be_bytes(body[at..at + 4].try_into().unwrap());
        assert_eq!((word(0), word(4)), (1_700_000_000, 500_000));
        assert_eq!(word(8) as i32, 435_000_000);
        assert_eq!(word(12) as i32, -792_500_000);
        assert_eq!(word(16) as i32, 76_125);
        // After speed, course, utm_e and utm_n (doubles): quality,
        // satellites, hdop and vdop.
        assert_eq!((word(52), word(56), word(60), word(64)), (2, 9, 15, 20));
        assert_eq!(f64::from_be_bytes(body[76..84].try_into().unwrap()), 1.5);
    }

    /// A Troupe request asked of a Player server is the REQ the bridge would
    /// turn back into that request, and the server's ACK for a reply comes
    /// back as that reply.
    #[test]
    fn forwarded_requests_and_replies_round_trip() {
        use troupe_msgs::{Pose3d, Size3d};
        let geom = position2d::Geom {
            pose: Pose3d::planar(-0.04, 0.0, 0.0),
            size: Size3d {
                width: 0.38,
                length: 0.44,
                height: 0.22,
            },
        };
        let laser_cfg = laser::Config {
            min_angle: -1.5,
            max_angle: 1.5,
            resolution: 0.5,
            max_range: 8.0,
            range_res: 0.01,
            intensity: true,
            scanning_frequency: 10.0,
        };
        let ranger_geom = ranger::Geom {
            pose: Pose3d::planar(0.1, 0.0, 0.0),
            size: geom.size,
            element_poses: vec![
                Pose3d::planar(0.0, 0.1, 1.0),
                Pose3d::planar(0.0, -0.1, -1.0),
            ],
            element_sizes: vec![geom.size, geom.size],
        };
        let info = map::Info {
            width: 500,
            height: 400,
            resolution: 0.032,
            origin: Pose2d::new(-8.0, -6.4, 0.0),
        };
        let cases: Vec<(Interface, Vec<u8>, Vec<u8>)> = vec![
            (
                Interface::Position2d,
                encode(&position2d::GetGeom, 0.0),
                encode(&geom, 0.0),
            ),
            (
                Interface::Position2d,
                encode(&position2d::MotorPower { state: true }, 0.0),
                encode(&common::Ack, 0.0),
            ),
            (
                Interface::Position2d,
                encode(
                    &position2d::SetOdom {
                        pose: Pose2d::new(1.0, 2.0, 0.5),
                    },
                    0.0,
                ),
                encode(&common::Ack, 0.0),
            ),
            (
                Interface::Laser,
                encode(&laser::GetConfig, 0.0),
                encode(&laser_cfg, 0.0),
            ),
            (
                Interface::Laser,
                encode(&laser::SetConfig { config: laser_cfg }, 0.0),
                encode(&laser_cfg, 0.0),
            ),
            (
                Interface::Ranger,
                encode(&ranger::GetGeom, 0.0),
                encode(&ranger_geom, 0.0),
            ),
            (
                Interface::Map,
                encode(&map::GetInfo, 0.0),
                encode(&info, 0.0),
            ),
            (
                Interface::Sonar,
                encode(&common::Power { state: false }, 0.0),
                encode(&common::Ack, 0.0),
            ),
        ];
        let any = |p: &[u8]| troupe_msgs::decode_any(p).unwrap().msg;
        for (iface, q, want) in cases {
            let out = request_to_player(iface, &q).unwrap_or_else(|| panic!("{:?}", any(&q)));
            let Some(ToDevice::Request { payload, reply, .. }) =
                from_player(iface, REQ, out.subtype, &out.body, 0.0).unwrap()
            else {
                panic!("{:?} is not a request", any(&q));
            };
            assert_eq!(any(&payload), any(&q));
            // The ACK a bridge (Player's layout) sends for `want`.
            let ack = reply(&want).unwrap();
            let back = (out.reply)(&ack, 3.0).unwrap();
            assert_eq!(any(&back), any(&want), "{:?}", any(&q));
        }
        assert!(request_to_player(Interface::Map, &encode(&map::GetVector, 0.0)).is_none());
        assert!(request_to_player(
            Interface::Position2d,
            &encode(&common::Power { state: true }, 0.0)
        )
        .is_none());
    }

    /// A Troupe command sent to a Player server is the CMD the bridge
    /// would have turned back into that command.
    #[test]
    fn exported_commands_are_what_the_bridge_imports() {
        let cmds: Vec<Vec<u8>> = vec![
            encode(
                &position2d::CmdVel {
                    vel: Pose2d::new(0.3, 0.0, 0.2),
                    state: true,
                },
                1.0,
            ),
            encode(
                &position2d::CmdPos {
                    pos: Pose2d::new(1.0, 2.0, 0.5),
                    vel: Pose2d::new(0.1, 0.0, 0.0),
                    state: true,
                },
                1.0,
            ),
            encode(
                &planner::Goal {
                    goal: Pose2d::new(-4.5, -5.5, 0.0),
                },
                1.0,
            ),
            encode(&gripper::Close, 1.0),
            encode(&dio::Cmd { count: 4, bits: 9 }, 1.0),
        ];
        let iface_of = |p: &[u8]| match troupe_msgs::decode_any(p).unwrap().msg {
            AnyMsg::PlannerGoal(_) => Interface::Planner,
            AnyMsg::GripperClose(_) => Interface::Gripper,
            AnyMsg::DioCmd(_) => Interface::Dio,
            _ => Interface::Position2d,
        };
        for c in cmds {
            let (subtype, body) = command_to_player(&c).unwrap();
            let Some(ToDevice::Command { payload, .. }) =
                from_player(iface_of(&c), CMD, subtype, &body, 1.0).unwrap()
            else {
                panic!("not a command");
            };
            assert_eq!(
                troupe_msgs::decode_any(&payload).unwrap().msg,
                troupe_msgs::decode_any(&c).unwrap().msg
            );
        }
        assert!(command_to_player(&encode(&common::Ack, 0.0)).is_none());
        assert!(command_to_player(b"junk").is_none());
    }

    fn hex(s: &str) -> Vec<u8> {
        (0..s.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
            .collect()
    }

    fn req_payload(t: Option<ToDevice>) -> (&'static str, Vec<u8>, ReplyFn) {
        match t.unwrap() {
            ToDevice::Request {
                name,
                payload,
                reply,
            } => (name, payload, reply),
            c => panic!("{c:?}"),
        }
    }

    #[test]
    fn position2d_state_is_52_bytes_as_in_the_transcript() {
        let d = position2d::Data {
            pose: Pose2d::new(-6.946, -6.947, 0.5),
            vel: Pose2d::default(),
            stall: false,
        };
        let (iface, sub, body) = to_player(&AnyMsg::Position2dData(d)).unwrap();
        assert_eq!((iface, sub, body.len()), (Interface::Position2d, 1, 52));
        assert_eq!(&body[48..], &[0, 0, 0, 0]);
    }

    #[test]
    fn cmd_vel_from_libplayerc_bytes() {
        // c-pull-position-laser #92: vel (0.3, 0, 0.2) state 1.
        let body = hex(concat!(
            "3fd3333333333333",
            "0000000000000000",
            "3fc999999999999a",
            "00000001"
        ));
        let t = from_player(Interface::Position2d, CMD, 1, &body, 1.0).unwrap();
        let Some(ToDevice::Command { name, payload }) = t else {
            panic!("{t:?}")
        };
        assert_eq!(name, "vel");
        let c = decode::<position2d::CmdVel>(&payload).unwrap().msg;
        assert_eq!(c.vel, Pose2d::new(0.3, 0.0, 0.2));
        assert!(c.state);
    }

    #[test]
    fn simulation_get_pose2d_reply_echoes_the_name_with_its_nul() {
        let mut w = Writer::new();
        w.string("r0");
        w_pose2d(&mut w, &Pose2d::default());
        let (name, payload, reply) =
            req_payload(from_player(Interface::Simulation, REQ, 1, &w.finish(), 0.0).unwrap());
        assert_eq!(name, "get_pose2d");
        let q = decode::<simulation::GetPose2d>(&payload).unwrap().msg;
        assert_eq!(q.name, "r0");
        let ack = reply(&encode(
            &simulation::Pose2dOf {
                name: "r0".into(),
                pose: Pose2d::new(-6.946, -6.947, 0.5),
            },
            0.0,
        ))
        .unwrap();
        assert_eq!(ack.len(), 36);
        assert_eq!(&ack[..12], &[0, 0, 0, 3, 0, 0, 0, 3, b'r', b'0', 0, 0]);
    }

    #[test]
    fn colour_property_is_four_little_endian_floats() {
        let v = property_value("color", &hex("00000000000000000000803f0000803f"));
        assert_eq!(
            v,
            simulation::Value::Color(Color {
                r: 0.0,
                g: 0.0,
                b: 1.0,
                a: 1.0
            })
        );
        assert_eq!(
            property_bytes(
                &simulation::Value::Color(Color {
                    r: 1.0,
                    g: 0.0,
                    b: 0.0,
                    a: 1.0
                }),
                16
            ),
            hex("0000803f00000000000000000000803f")
        );
        // Stage's time: a uint64 of microseconds, in a buffer of 8 bytes.
        assert_eq!(
            property_bytes(&simulation::Value::Int(41_900_000), 8),
            41_900_000u64.to_le_bytes()
        );
    }

    #[test]
    fn map_tile_is_zlib_and_decompresses_to_the_cells() {
        let d = map::Data {
            col: 0,
            row: 0,
            width: 3,
            height: 2,
            cells: vec![-1, 0, 1, 1, -1, -1],
        };
        let mut w = Writer::new();
        map_data(&d, &mut w);
        let b = w.finish();
        let mut r = Reader::new(&b);
        for _ in 0..4 {
            r.u32().unwrap();
        }
        let count = r.u32().unwrap() as usize;
        assert_eq!(r.i32().unwrap(), 1);
        let z = &b[28..28 + count];
        assert_eq!(&z[..2], &[0x78, 0x9c]);
        let mut out = Vec::new();
        std::io::Read::read_to_end(&mut flate2::read::ZlibDecoder::new(z), &mut out).unwrap();
        assert_eq!(out, [255, 0, 1, 1, 255, 255]);
        assert_eq!(b.len() % 4, 0);
    }

    #[test]
    fn truncated_and_padded_bodies_name_the_message() {
        let e = from_player(Interface::Position2d, CMD, 1, &[0; 8], 0.0).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("position2d CMD subtype 1: body ends"),
            "{e}"
        );
        let e = from_player(Interface::Planner, REQ, 2, &[0; 8], 0.0).unwrap_err();
        assert!(e.to_string().contains("unexpected bytes"), "{e}");
    }

    #[test]
    fn unserved_subtypes_are_none() {
        assert!(from_player(Interface::Position2d, REQ, 7, &[0; 12], 0.0)
            .unwrap()
            .is_none());
        assert!(from_player(Interface::Camera, REQ, 1, &[], 0.0)
            .unwrap()
            .is_none());
    }

    #[test]
    fn ranger_ranges_are_counted_twice() {
        let (iface, sub, body) = to_player(&AnyMsg::RangerRanges(ranger::Ranges {
            ranges: vec![1.0; 16],
        }))
        .unwrap();
        assert_eq!((iface, sub, body.len()), (Interface::Ranger, 1, 136));
    }
}
