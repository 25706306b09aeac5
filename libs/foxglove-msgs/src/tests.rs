use super::*;
use foxglove::Decode;
use troupe_msgs::{laser, Interface};

fn dev(interface: Interface, index: u32) -> Device {
    Device {
        robot: 6665,
        interface,
        index,
    }
}

fn key(interface: Interface) -> String {
    keys::data(&dev(interface, 0))
}

fn decode<T: Decode>(m: &Message) -> T {
    assert_eq!(m.kind.encoding(), PROTOBUF);
    T::decode(m.data.as_slice()).unwrap_or_else(|e| panic!("{}: {e}", m.topic))
}

fn schema_name(m: &Message) -> String {
    m.kind.schema().map(|s| s.name).unwrap_or_default()
}

#[test]
fn a_scan_is_a_laser_scan_in_the_sensor_s_frame() {
    let scan = laser::Scan {
        min_angle: -1.5,
        max_angle: 1.5,
        resolution: 0.5,
        max_range: 8.0,
        ranges: vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0],
        intensity: vec![0, 1, 0, 0, 0, 0, 2],
        id: 3,
    };
    let out = Translator::new().translate(
        &key(Interface::Laser),
        2_500_000_000,
        &AnyMsg::LaserScan(scan),
    );
    assert_eq!(out.len(), 1);
    assert_eq!(out[0].topic, "/robot/6665/laser/0");
    assert_eq!(schema_name(&out[0]), "foxglove.LaserScan");
    let m: LaserScan = decode(&out[0]);
    assert_eq!(m.frame_id, "robot_6665/laser_0");
    assert_eq!(m.ranges, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]);
    assert_eq!((m.start_angle, m.end_angle), (-1.5, 1.5));
    let t = m.timestamp.unwrap();
    assert_eq!((t.sec(), t.nsec()), (2, 500_000_000));
}

#[test]
fn odometry_then_an_estimate_join_the_tree() {
    let mut t = Translator::new();
    let d = position2d::Data {
        pose: Pose2d {
            x: 1.0,
            y: 0.0,
            yaw: 0.0,
        },
        ..Default::default()
    };
    let out = t.translate(&key(Interface::Position2d), 0, &AnyMsg::Position2dData(d));
    let topics: Vec<&str> = out.iter().map(|m| m.topic.as_str()).collect();
    assert_eq!(topics, ["/robot/6665/position2d/0", TF]);
    let tf: FrameTransforms = decode(&out[1]);
    assert_eq!(
        (
            tf.transforms[0].parent_frame_id.as_str(),
            tf.transforms[0].child_frame_id.as_str()
        ),
        ("robot_6665/odom", "robot_6665/base_link")
    );
    let hs = localize::Hypoths {
        hypoths: vec![localize::Hypoth {
            mean: Pose2d {
                x: 3.0,
                y: 2.0,
                yaw: 0.0,
            },
            cov: [0.0; 6],
            weight: 1.0,
        }],
        ..Default::default()
    };
    let out = t.translate(&key(Interface::Localize), 0, &AnyMsg::LocalizeHypoths(hs));
    assert!(out[0].latched, "an estimate stands until the next");
    let tf: FrameTransforms = decode(&out[1]);
    let m2o = &tf.transforms[0];
    assert_eq!(m2o.parent_frame_id, MAP_FRAME);
    let at = m2o.translation.as_ref().unwrap();
    // Odometry's origin is at (2, 2) in the map: (3, 2) minus (1, 0).
    assert!((at.x - 2.0).abs() < 1e-12 && (at.y - 2.0).abs() < 1e-12);
}

#[test]
fn a_whole_map_is_a_latched_grid_and_a_tile_is_json() {
    let mut t = Translator::new();
    let k = key(Interface::Map);
    let data = map::Data {
        col: 0,
        row: 0,
        width: 2,
        height: 2,
        cells: vec![-1, 0, 1, 1],
    };
    let info = map::Info {
        width: 2,
        height: 2,
        resolution: 0.5,
        origin: Pose2d {
            x: -1.0,
            y: -2.0,
            yaw: 0.0,
        },
    };
    assert!(t.translate(&k, 0, &AnyMsg::MapInfo(info)).is_empty());
    let out = t.translate(&k, 0, &AnyMsg::MapData(data.clone()));
    assert!(out[0].latched);
    let g: Grid = decode(&out[0]);
    assert_eq!(g.data.as_ref(), [0, 0xff, 100, 100]);
    assert_eq!((g.column_count, g.row_stride), (2, 2));
    let tile = map::Data {
        width: 1,
        cells: vec![-1, 1],
        ..data
    };
    let out = t.translate(&k, 0, &AnyMsg::MapData(tile));
    assert_eq!(out[0].kind.encoding(), JSON);
    assert_eq!(out[0].topic, "/robot/6665/map/0/data");
    let v: serde_json::Value = serde_json::from_slice(&out[0].data).unwrap();
    assert_eq!(v["width"], 1);
    assert_eq!(schema_name(&out[0]), "map/data@1");
}

#[test]
fn a_world_is_a_still_scene_and_its_poses_move_the_rest() {
    let mut t = Translator::new();
    let k = key(Interface::Simulation);
    let square = vec![vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]];
    let model = |name: &str, moves: bool| simulation::Model {
        name: name.into(),
        polys: square.clone(),
        moves,
        ..Default::default()
    };
    let poses = simulation::Poses {
        time: 1.0,
        poses: vec![(1, [5.0, 6.0, 0.0])],
    };
    let early = t.translate(&k, 0, &AnyMsg::SimulationPoses(poses.clone()));
    assert_eq!(early[0].kind.encoding(), JSON, "no world to draw them in");
    let w = simulation::World {
        models: vec![model("walls", false), model("r0", true)],
        ..Default::default()
    };
    let out = t.translate(&k, 0, &AnyMsg::SimulationWorld(w));
    let still: SceneUpdate = decode(&out[0]);
    assert_eq!(out[0].topic, "/robot/6665/simulation/0/world");
    assert!(out[0].latched);
    assert_eq!(still.entities.len(), 1);
    assert_eq!(still.entities[0].id, "0:walls");
    // Four edges, two points each.
    assert_eq!(still.entities[0].lines[0].points.len(), 8);
    let out = t.translate(&k, 0, &AnyMsg::SimulationPoses(poses));
    let moving: SceneUpdate = decode(&out[0]);
    assert_eq!(out[0].topic, "/robot/6665/simulation/0/scene");
    assert_eq!(moving.entities[0].id, "1:r0");
    let at = moving.entities[0].lines[0].pose.as_ref().unwrap();
    assert_eq!(at.position.as_ref().unwrap().x, 5.0);
}

#[test]
fn a_planner_s_waypoints_are_its_latched_path_in_the_map() {
    let w = troupe_msgs::planner::Waypoints {
        waypoints: vec![Pose2d::default(), Pose2d::new(5.0, 0.0, 0.0)],
    };
    let out =
        Translator::new().translate(&key(Interface::Planner), 0, &AnyMsg::PlannerWaypoints(w));
    assert_eq!(out[0].topic, "/robot/6665/planner/0/path");
    assert!(out[0].latched);
    let p: PosesInFrame = decode(&out[0]);
    assert_eq!((p.frame_id.as_str(), p.poses.len()), (MAP_FRAME, 2));
    assert_eq!(p.poses[1].position.as_ref().unwrap().x, 5.0);
}

#[test]
fn camera_images_are_raw_or_compressed_images() {
    use troupe_msgs::camera;
    let k = key(Interface::Camera);
    let mut t = Translator::new();
    let raw = camera::Data {
        width: 2,
        height: 1,
        bpp: 8,
        format: camera::FORMAT_MONO8,
        fdiv: 0,
        compression: camera::COMPRESS_RAW,
        image: vec![10, 20],
    };
    let out = t.translate(&k, 0, &AnyMsg::CameraData(raw.clone()));
    assert_eq!(schema_name(&out[0]), "foxglove.RawImage");
    let m: RawImage = decode(&out[0]);
    assert_eq!(
        (m.encoding.as_str(), m.step, m.frame_id.as_str()),
        ("mono8", 2, "robot_6665/camera_0")
    );
    assert_eq!(&m.data[..], [10, 20]);
    let jpeg = camera::Data {
        compression: camera::COMPRESS_JPEG,
        image: vec![0xFF, 0xD8],
        ..raw.clone()
    };
    let out = t.translate(&k, 0, &AnyMsg::CameraData(jpeg));
    assert_eq!(schema_name(&out[0]), "foxglove.CompressedImage");
    let m: CompressedImage = decode(&out[0]);
    assert_eq!(
        (m.format.as_str(), &m.data[..]),
        ("jpeg", &[0xFF, 0xD8][..])
    );
    // Bytes too few for the size: JSON, as anything without a schema.
    let short = camera::Data {
        image: vec![1],
        ..raw
    };
    let out = t.translate(&k, 0, &AnyMsg::CameraData(short));
    assert_eq!(out[0].kind.encoding(), JSON);
}
