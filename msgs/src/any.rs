//! Decoding a payload of any known schema, for tools that print what they see.

use serde::{Deserializer, Serialize, Serializer};

use crate::codec::{decode_body, split, DecodeError, Message, Route, Stamped};
use crate::iface::*;

macro_rules! any {
    ($( $variant:ident($ty:ty) ),* $(,)?) => {
        /// Any message this crate defines, tagged by interface and name.
        #[derive(Debug, Clone, PartialEq, Serialize)]
        #[allow(missing_docs)]
        pub enum AnyMsg {
            $( $variant($ty), )*
        }

        /// Every schema tag this build knows.
        pub const SCHEMAS: &[&str] = &[$( <$ty as Message>::SCHEMA, )*];

        /// Decodes a payload of any known schema.
        ///
        /// # Errors
        ///
        /// [`DecodeError::UnknownSchema`] for a tag this build does not know,
        /// otherwise the errors of [`crate::decode`].
        pub fn decode_any(payload: &[u8]) -> Result<Stamped<AnyMsg>, DecodeError> {
            let (tag, stamp, body) = split(payload)?;
            let msg = match tag {
                $( <$ty as Message>::SCHEMA => AnyMsg::$variant(decode_body::<$ty>(tag, body)?), )*
                other => return Err(DecodeError::UnknownSchema(other.to_owned())),
            };
            Ok(Stamped { stamp, msg })
        }

        /// Every schema with its route: the commands and requests of each interface.
        const ROUTES: &[(&str, Option<Route>)] = &[$( (<$ty as Message>::SCHEMA, <$ty as Message>::ROUTE), )*];

        /// Serializes the default value of the message of schema `schema`
        /// (what a tool fills in from a command line); `None` for an unknown schema.
        ///
        /// # Errors
        ///
        /// The serializer's.
        pub fn default_of<S: Serializer>(schema: &str, s: S) -> Option<Result<S::Ok, S::Error>> {
            match schema {
                $( <$ty as Message>::SCHEMA => Some(<$ty as Default>::default().serialize(s)), )*
                _ => None,
            }
        }

        /// Encodes a message of schema `schema` read from any serde format
        /// (JSON from a command line, a Python dict…), stamped `stamp`.
        /// `None` when this build knows no such schema.
        ///
        /// # Errors
        ///
        /// The format's error when the value does not fit the schema.
        pub fn encode_from<'de, D: Deserializer<'de>>(
            schema: &str,
            de: D,
            stamp: f64,
        ) -> Result<Option<Vec<u8>>, D::Error> {
            Ok(match schema {
                $( <$ty as Message>::SCHEMA => {
                    let m: $ty = serde::Deserialize::deserialize(de)?;
                    Some(crate::codec::encode(&m, stamp))
                } )*
                _ => None,
            })
        }

        impl AnyMsg {
            /// The payload of this message stamped `stamp`, as [`crate::encode`] makes it.
            pub fn encode(&self, stamp: f64) -> Vec<u8> {
                match self {
                    $( AnyMsg::$variant(m) => crate::codec::encode(m, stamp), )*
                }
            }

            /// Its schema tag, `laser/scan@1`.
            pub fn schema(&self) -> &'static str {
                match self {
                    $( AnyMsg::$variant(_) => <$ty as Message>::SCHEMA, )*
                }
            }

            /// Serializes the message alone, without the variant's name
            /// around it: `{"ranges": …}` rather than `{"LaserScan": {"ranges": …}}`.
            ///
            /// # Errors
            ///
            /// The serializer's.
            pub fn serialize_body<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                match self {
                    $( AnyMsg::$variant(m) => m.serialize(s), )*
                }
            }
        }
    };
}

any! {
    Ack(common::Ack), Nack(common::Nack), Power(common::Power),
    SimClock(sim::Clock),
    Position2dData(position2d::Data), Position2dGeom(position2d::Geom),
    Position2dCmdVel(position2d::CmdVel), Position2dCmdPos(position2d::CmdPos),
    Position2dCmdCar(position2d::CmdCar), Position2dGetGeom(position2d::GetGeom),
    Position2dMotorPower(position2d::MotorPower), Position2dSetOdom(position2d::SetOdom),
    Position2dResetOdom(position2d::ResetOdom), Position2dVelocityMode(position2d::VelocityMode),
    Position2dPositionMode(position2d::PositionMode),
    LaserScan(laser::Scan), LaserScanPose(laser::ScanPose), LaserGeom(laser::Geom),
    LaserConfig(laser::Config), LaserGetGeom(laser::GetGeom), LaserGetConfig(laser::GetConfig),
    LaserSetConfig(laser::SetConfig), LaserId(laser::Id), LaserGetId(laser::GetId),
    RangerRanges(ranger::Ranges), RangerIntensities(ranger::Intensities), RangerGeom(ranger::Geom),
    RangerConfig(ranger::Config), RangerGetGeom(ranger::GetGeom), RangerGetConfig(ranger::GetConfig),
    RangerSetConfig(ranger::SetConfig), RangerIntensityEnable(ranger::IntensityEnable),
    SonarRanges(sonar::Ranges), SonarGeom(sonar::Geom), SonarGetGeom(sonar::GetGeom),
    MapInfo(map::Info), MapGetInfo(map::GetInfo), MapData(map::Data), MapGetData(map::GetData),
    MapVector(map::Vector), MapGetVector(map::GetVector),
    LocalizeHypoths(localize::Hypoths), LocalizeSetPose(localize::SetPose),
    LocalizeParticles(localize::Particles), LocalizeGetParticles(localize::GetParticles),
    PlannerState(planner::State), PlannerGoal(planner::Goal), PlannerEnable(planner::Enable),
    PlannerWaypoints(planner::Waypoints), PlannerGetWaypoints(planner::GetWaypoints),
    SimulationGetPose2d(simulation::GetPose2d), SimulationPose2d(simulation::Pose2dOf),
    SimulationSetPose2d(simulation::SetPose2d), SimulationGetProperty(simulation::GetProperty),
    SimulationProperty(simulation::Property), SimulationSetProperty(simulation::SetProperty),
    SimulationStep(simulation::Step), SimulationGetPose3d(simulation::GetPose3d),
    SimulationPose3d(simulation::Pose3dOf), SimulationSetPose3d(simulation::SetPose3d),
    SimulationGetWorld(simulation::GetWorld), SimulationWorld(simulation::World),
    SimulationPoses(simulation::Poses),
    BlobfinderData(blobfinder::Data),
    GripperData(gripper::Data), GripperOpen(gripper::Open), GripperClose(gripper::Close),
    GripperStop(gripper::Stop), GripperGeom(gripper::Geom), GripperGetGeom(gripper::GetGeom),
    PtzData(ptz::Data), PtzCmd(ptz::Cmd),
    FiducialData(fiducial::Data), FiducialGeom(fiducial::Geom), FiducialGetGeom(fiducial::GetGeom),
    FiducialId(fiducial::Id), FiducialGetId(fiducial::GetId), FiducialSetId(fiducial::SetId),
    PowerData(power::Data),
    GpsData(gps::Data),
    CameraData(camera::Data),
    WsnData(wsn::Data),
    BumperData(bumper::Data), BumperGeom(bumper::Geom), BumperGetGeom(bumper::GetGeom),
    IrData(ir::Data), IrGeom(ir::Geom), IrGetGeom(ir::GetGeom),
    AioData(aio::Data), AioCmd(aio::Cmd),
    DioData(dio::Data), DioCmd(dio::Cmd),
    LogSetWriteState(log::SetWriteState), LogSetReadState(log::SetReadState),
    LogState(log::State), LogGetState(log::GetState), LogRewind(log::Rewind),
    LogSetFilename(log::SetFilename),
}

/// The commands and requests a device of `interface` takes: each route with
/// the schema of its message, the interface's own first, then those every
/// device may take (`power`).
pub fn routed(interface: crate::Interface) -> Vec<(Route, &'static str)> {
    let own = format!("{}/", interface.name());
    let mut out: Vec<(Route, &'static str)> = Vec::new();
    for prefix in [own.as_str(), "common/"] {
        for (schema, route) in ROUTES {
            if let (true, Some(r)) = (schema.starts_with(prefix), route) {
                if !out.iter().any(|(seen, _)| seen == r) {
                    out.push((*r, schema));
                }
            }
        }
    }
    out
}

/// The schema tag of message kind `kind` (`position2d/cmd_vel`), whatever
/// its version: what tools that take a kind by name send.
pub fn schema_for(kind: &str) -> Option<&'static str> {
    SCHEMAS
        .iter()
        .copied()
        .find(|s| s.split_once('@').is_some_and(|(k, _)| k == kind))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::encode;

    #[test]
    fn schema_tags_are_unique_short_and_versioned() {
        let mut seen = std::collections::HashSet::new();
        for s in SCHEMAS {
            assert!(seen.insert(s), "duplicate schema {s}");
            assert!(s.len() < 64 && s.contains('@'), "{s}");
        }
    }

    #[test]
    fn decode_any_finds_the_type_by_tag() {
        let bytes = encode(
            &map::Info {
                width: 3,
                ..Default::default()
            },
            2.0,
        );
        let got = decode_any(&bytes).unwrap();
        assert_eq!(got.stamp, 2.0);
        assert!(matches!(
            got.msg,
            AnyMsg::MapInfo(map::Info { width: 3, .. })
        ));
        let json = serde_json::to_string(&got.msg).unwrap();
        assert!(json.starts_with("{\"MapInfo\":{\"width\":3"), "{json}");
    }

    #[test]
    fn encode_from_reads_any_format_and_the_body_serializes_bare() {
        let schema = schema_for("position2d/cmd_vel").unwrap();
        assert_eq!(schema, position2d::CmdVel::SCHEMA);
        let json = r#"{"vel": {"x": 0.5, "y": 0, "yaw": 0.25}, "state": true}"#;
        let mut de = serde_json::Deserializer::from_str(json);
        let bytes = encode_from(schema, &mut de, 3.0).unwrap().unwrap();
        let got = decode_any(&bytes).unwrap();
        assert_eq!(got.stamp, 3.0);
        assert_eq!(got.msg.schema(), schema);
        let mut out = Vec::new();
        got.msg
            .serialize_body(&mut serde_json::Serializer::new(&mut out))
            .unwrap();
        assert_eq!(
            String::from_utf8(out).unwrap(),
            r#"{"vel":{"x":0.5,"y":0.0,"yaw":0.25},"state":true}"#
        );
        let mut de = serde_json::Deserializer::from_str(r#"{"vel": 1}"#);
        assert!(encode_from(schema, &mut de, 0.0).is_err());
        let mut de = serde_json::Deserializer::from_str("null");
        assert_eq!(encode_from("nope@1", &mut de, 0.0).unwrap(), None);
        assert_eq!(schema_for("position2d/cmd"), None);
    }

    #[test]
    fn every_interface_routes_its_commands_and_requests() {
        let routes = routed(crate::Interface::Position2d);
        assert!(routes.contains(&(Route::Command("vel"), position2d::CmdVel::SCHEMA)));
        assert!(routes.contains(&(Route::Request("geom"), position2d::GetGeom::SCHEMA)));
        assert!(routes.contains(&(Route::Request("power"), common::Power::SCHEMA)));
        assert!(!routes.iter().any(|(_, s)| *s == position2d::Data::SCHEMA));
        let v = default_of(position2d::CmdVel::SCHEMA, serde_json::value::Serializer)
            .unwrap()
            .unwrap();
        assert_eq!(v["vel"]["yaw"], 0.0);
    }

    #[test]
    fn unknown_schema_is_named() {
        let mut bytes = vec![7];
        bytes.extend_from_slice(b"nope@99");
        bytes.extend_from_slice(&0f64.to_le_bytes());
        assert_eq!(
            decode_any(&bytes).unwrap_err().to_string(),
            "unknown schema `nope@99`"
        );
    }
}
