use super::*;
use troupe_msgs::{localize, Interface};

fn dev(interface: Interface, index: u32) -> Device {
    Device {
        robot: 6665,
        interface,
        index,
    }
}

fn key(d: &Device) -> String {
    keys::data(d)
}

/// Robot 6665's odometry at `x, y, yaw`, through `t`.
fn odometry(t: &mut Translator, x: f64, y: f64, yaw: f64) -> Vec<Out> {
    let d = position2d::Data {
        pose: Pose2d { x, y, yaw },
        ..Default::default()
    };
    let k = key(&dev(Interface::Position2d, 0));
    t.translate(&k, 0, &AnyMsg::Position2dData(d)).unwrap()
}

/// Robot 6665's localizer's one hypothesis, through `t`.
fn estimate(t: &mut Translator, mean: Pose2d, cov: [f64; 6]) -> Vec<Out> {
    let hs = localize::Hypoths {
        hypoths: vec![localize::Hypoth {
            mean,
            cov,
            weight: 1.0,
        }],
        ..Default::default()
    };
    let k = key(&dev(Interface::Localize, 0));
    t.translate(&k, 0, &AnyMsg::LocalizeHypoths(hs)).unwrap()
}

fn decode<T: serde::de::DeserializeOwned>(o: &Out) -> T {
    assert_eq!(o.data[..4], [0, 1, 0, 0], "CDR, little-endian");
    cdr::deserialize(&o.data).unwrap()
}

#[test]
fn a_header_is_laid_out_as_cdr_says() {
    let h = Header {
        stamp: Time { sec: 1, nanosec: 2 },
        frame_id: "ab".into(),
    };
    // Encapsulation, sec, nanosec, the string's length with its NUL, "ab\0".
    assert_eq!(
        cdr(&h),
        [0, 1, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0, 3, 0, 0, 0, b'a', b'b', 0]
    );
}

#[test]
fn a_scan_keeps_its_ranges_angles_and_stamp() {
    let laser = dev(Interface::Laser, 0);
    let scan = laser::Scan {
        min_angle: -1.5,
        max_angle: 1.5,
        resolution: 0.5,
        max_range: 8.0,
        ranges: vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0],
        intensity: vec![0, 1, 0, 0, 0, 0, 2],
        id: 3,
    };
    let outs = Translator::new()
        .translate(
            &key(&laser),
            2_500_000_000,
            &AnyMsg::LaserScan(scan.clone()),
        )
        .unwrap();
    assert_eq!(outs.len(), 1);
    assert_eq!(outs[0].topic, "/robot_6665/laser_0");
    assert_eq!(outs[0].ty, Type::LaserScan);
    let m: LaserScan = decode(&outs[0]);
    assert_eq!(
        m.header.stamp,
        Time {
            sec: 2,
            nanosec: 500_000_000
        }
    );
    assert_eq!(m.header.frame_id, "robot_6665/laser_0");
    assert_eq!(m.ranges, scan.ranges);
    assert_eq!(m.intensities, [0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 2.0]);
    assert_eq!(
        (m.angle_min, m.angle_max, m.angle_increment, m.range_max),
        (-1.5, 1.5, 0.5, 8.0)
    );
}

#[test]
fn odometry_and_localization_join_in_one_tree() {
    let mut t = Translator::new();
    let outs = odometry(&mut t, 1.0, 0.0, 0.3);
    let o: Odometry = decode(&outs[0]);
    assert_eq!(
        (o.header.frame_id.as_str(), o.child_frame_id.as_str()),
        ("robot_6665/odom", "robot_6665/base_link")
    );
    assert!((o.pose.pose.orientation.yaw() - 0.3).abs() < 1e-12);
    assert_eq!(outs[1].topic, TF);

    // amcl puts the robot at (2, 1, pi/2) in the map.
    let mean = Pose2d {
        x: 2.0,
        y: 1.0,
        yaw: std::f64::consts::FRAC_PI_2,
    };
    let outs = estimate(&mut t, mean, [0.1, 0.2, 0.3, 0.01, 0.02, 0.03]);
    let p: PoseWithCovarianceStamped = decode(&outs[0]);
    assert_eq!(p.header.frame_id, MAP_FRAME);
    let c = p.pose.covariance.0;
    assert_eq!(
        (c[0], c[7], c[35], c[1], c[6], c[11], c[30]),
        (0.1, 0.2, 0.3, 0.01, 0.01, 0.02, 0.03)
    );
    // map -> odom, then odom -> base_link, gives amcl's pose.
    let tf: TfMessage = decode(&outs[1]);
    let m2o = &tf.transforms[0];
    assert_eq!(m2o.child_frame_id, "robot_6665/odom");
    let m2o = Pose2d {
        x: m2o.transform.translation.x,
        y: m2o.transform.translation.y,
        yaw: m2o.transform.rotation.yaw(),
    };
    let got = compose(
        m2o,
        Pose2d {
            x: 1.0,
            y: 0.0,
            yaw: 0.3,
        },
    );
    assert!(
        (got.x - 2.0).abs() < 1e-9 && (got.y - 1.0).abs() < 1e-9,
        "{got:?}"
    );
    assert!((got.yaw - mean.yaw).abs() < 1e-9);
}

#[test]
fn a_map_becomes_a_grid_once_its_info_is_known() {
    let mut t = Translator::new();
    let m = dev(Interface::Map, 0);
    let data = map::Data {
        col: 0,
        row: 0,
        width: 2,
        height: 2,
        cells: vec![-1, 0, 1, 1],
    };
    assert_eq!(
        t.translate(&key(&m), 0, &AnyMsg::MapData(data.clone())),
        None,
        "no info yet"
    );
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
    assert_eq!(
        t.translate(&key(&m), 0, &AnyMsg::MapInfo(info)),
        Some(vec![])
    );
    let outs = t
        .translate(&key(&m), 0, &AnyMsg::MapData(data.clone()))
        .unwrap();
    let g: OccupancyGrid = decode(&outs[0]);
    assert_eq!(g.data, [0, -1, 100, 100]);
    assert_eq!(
        (g.info.width, g.info.height, g.info.resolution),
        (2, 2, 0.5)
    );
    assert_eq!(
        (g.info.origin.position.x, g.info.origin.position.y),
        (-1.0, -2.0)
    );
    let tile = map::Data {
        width: 1,
        cells: vec![-1, 1],
        ..data
    };
    assert_eq!(
        t.translate(&key(&m), 0, &AnyMsg::MapData(tile)),
        None,
        "a tile has no ROS form"
    );
}

#[test]
fn a_sonar_array_is_one_range_per_element_in_its_own_frame() {
    let s = dev(Interface::Sonar, 0);
    let mut t = Translator::new();
    let geom = sonar::Geom {
        poses: vec![
            Pose3d {
                x: 0.1,
                yaw: 0.5,
                ..Default::default()
            },
            Pose3d::default(),
        ],
    };
    let outs = t.translate(&key(&s), 0, &AnyMsg::SonarGeom(geom)).unwrap();
    let tf: TfMessage = decode(&outs[0]);
    assert_eq!(outs[0].topic, TF_STATIC);
    assert_eq!(tf.transforms[0].child_frame_id, "robot_6665/sonar_0/0");
    assert_eq!(tf.transforms[0].header.frame_id, "robot_6665/base_link");
    let outs = t
        .translate(
            &key(&s),
            0,
            &AnyMsg::SonarRanges(sonar::Ranges {
                ranges: vec![1.5, 2.5],
            }),
        )
        .unwrap();
    let r: Vec<Range> = outs.iter().map(decode).collect();
    assert_eq!((r[0].range, r[1].range), (1.5, 2.5));
    assert_eq!(r[1].header.frame_id, "robot_6665/sonar_0/1");
}

#[test]
fn a_ranger_scans_by_its_configuration_and_without_one_has_no_ros_form() {
    let r = dev(Interface::Ranger, 1);
    let mut t = Translator::new();
    let ranges = AnyMsg::RangerRanges(ranger::Ranges {
        ranges: vec![1.0, 2.0, 3.0],
    });
    assert_eq!(t.translate(&key(&r), 0, &ranges), None);
    let c = ranger::Config {
        min_angle: -1.0,
        max_angle: 1.0,
        angular_res: 1.0,
        max_range: 5.0,
        frequency: 10.0,
        ..Default::default()
    };
    t.translate(&key(&r), 0, &AnyMsg::RangerConfig(c));
    let s: LaserScan = decode(&t.translate(&key(&r), 0, &ranges).unwrap()[0]);
    assert_eq!(s.ranges, [1.0, 2.0, 3.0]);
    assert_eq!(
        (s.angle_min, s.angle_increment, s.range_max, s.scan_time),
        (-1.0, 1.0, 5.0, 0.1)
    );
}

#[test]
fn the_clock_is_ros_clock_and_names_are_ros_names() {
    let outs = Translator::new()
        .translate(
            "sim/clock",
            1_000_000_007,
            &AnyMsg::SimClock(troupe_msgs::sim::Clock { time: 1.0 }),
        )
        .unwrap();
    let c: Clock = decode(&outs[0]);
    assert_eq!(
        (outs[0].topic.as_str(), c.clock),
        (CLOCK, Time { sec: 1, nanosec: 7 })
    );
    assert_eq!(
        topic_of_key("robot/7000/position2d/1"),
        "/robot_7000/position2d_1"
    );
    assert_eq!(topic_of_key("fleet/2/status-x"), "/fleet/_2/status_x");
}

#[test]
fn every_definition_defines_every_type_it_uses() {
    const PRIMITIVES: &[&str] = &[
        "bool", "byte", "char", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64",
        "uint64", "float32", "float64", "string",
    ];
    for ty in Type::ALL {
        let text = ty.definition();
        let sections: Vec<&str> = text.split(&"=".repeat(80)).collect();
        let own_package = ty.name().split('/').next().unwrap().to_owned();
        let defined: Vec<String> = sections[1..]
            .iter()
            .map(|s| {
                s.trim_start()
                    .lines()
                    .next()
                    .unwrap()
                    .trim_start_matches("MSG: ")
                    .to_owned()
            })
            .collect();
        let mut packages = vec![own_package];
        packages.extend(
            defined
                .iter()
                .map(|d| d.split('/').next().unwrap().to_owned()),
        );
        for (section, package) in sections.iter().zip(&packages) {
            for line in section
                .lines()
                .filter(|l| !l.is_empty() && !l.starts_with("MSG:"))
            {
                let field = line.split_whitespace().next().unwrap();
                let base = field.split('[').next().unwrap();
                if PRIMITIVES.contains(&base) || line.contains('=') {
                    continue;
                }
                let full = if base.contains('/') {
                    base.to_owned()
                } else {
                    format!("{package}/{base}")
                };
                assert!(
                    defined.contains(&full),
                    "{}: {full} is used but not defined",
                    ty.name()
                );
            }
        }
        assert_eq!(Type::from_name(ty.name()), Some(ty));
    }
}

#[test]
fn an_estimate_before_any_odometry_is_joined_when_odometry_comes() {
    let mut t = Translator::new();
    let fix = Pose2d {
        x: 3.0,
        y: 0.0,
        yaw: 0.0,
    };
    let outs = estimate(&mut t, fix, [0.0; 6]);
    assert_eq!(outs.len(), 1, "no odometry yet: no map -> odom");
    let outs = odometry(&mut t, 1.0, 0.0, 0.0);
    let joined: Vec<TransformStamped> = outs[1..]
        .iter()
        .flat_map(|o| decode::<TfMessage>(o).transforms)
        .filter(|t| t.child_frame_id == "robot_6665/odom")
        .collect();
    assert_eq!(joined.len(), 1);
    assert_eq!(joined[0].transform.translation.x, 2.0);
    assert_eq!(odometry(&mut t, 1.0, 0.0, 0.0).len(), 2, "joined once");
}

#[test]
fn what_goes_out_comes_back_on_the_same_keys() {
    let mut t = Translator::new();
    let laser = dev(Interface::Laser, 0);
    let scan = laser::Scan {
        min_angle: -1.0,
        max_angle: 1.0,
        resolution: 1.0,
        max_range: 8.0,
        ranges: vec![1.0, 2.0, 3.0],
        intensity: vec![0, 1, 0],
        id: 0,
    };
    let odom = position2d::Data {
        pose: Pose2d {
            x: 1.0,
            y: 2.0,
            yaw: -0.5,
        },
        vel: Pose2d {
            x: 0.3,
            y: 0.0,
            yaw: 0.1,
        },
        stall: false,
    };
    let hyp = localize::Hypoths {
        hypoths: vec![localize::Hypoth {
            mean: Pose2d {
                x: 1.0,
                y: 2.0,
                yaw: 3.0,
            },
            cov: [0.1, 0.2, 0.3, 0.01, 0.02, 0.03],
            weight: 1.0,
        }],
        ..Default::default()
    };
    for (d, msg) in [
        (laser, AnyMsg::LaserScan(scan)),
        (dev(Interface::Position2d, 0), AnyMsg::Position2dData(odom)),
        (dev(Interface::Localize, 0), AnyMsg::LocalizeHypoths(hyp)),
    ] {
        let o = t
            .translate(&key(&d), 1_500_000_000, &msg)
            .unwrap()
            .remove(0);
        let k = back::key_of_topic(&o.topic).unwrap();
        assert_eq!(k, key(&d));
        let got = troupe_msgs::decode_any(&back::to_sample(o.ty, &k, &o.data).unwrap()).unwrap();
        assert_eq!(got.stamp, 1.5);
        match (got.msg, msg) {
            (AnyMsg::Position2dData(a), AnyMsg::Position2dData(b)) => {
                assert!((a.pose.yaw - b.pose.yaw).abs() < 1e-12 && a.vel == b.vel);
            }
            (AnyMsg::LocalizeHypoths(a), AnyMsg::LocalizeHypoths(b)) => {
                assert!((a.hypoths[0].mean.yaw - b.hypoths[0].mean.yaw).abs() < 1e-12);
                assert_eq!(a.hypoths[0].cov, b.hypoths[0].cov);
            }
            (a, b) => assert_eq!(a, b),
        }
    }
    assert_eq!(back::key_of_topic("/clock").as_deref(), Some("sim/clock"));
    assert_eq!(back::key_of_topic("/scan"), None);
    let clock = t
        .translate(
            "sim/clock",
            2_000_000_000,
            &AnyMsg::SimClock(troupe_msgs::sim::Clock { time: 2.0 }),
        )
        .unwrap()
        .remove(0);
    assert!(
        back::to_sample(clock.ty, "robot/6665/laser/0", &clock.data).is_err(),
        "a clock is no scan"
    );
    assert!(
        back::to_sample(Type::LaserScan, "robot/6665/laser/0", &[0, 1, 0, 0, 1]).is_err(),
        "cut short"
    );
}

/// A 2 x 1 image in format `format` of `bpp` bits, from `image`.
fn picture(format: u32, bpp: u32, image: &[u8]) -> troupe_msgs::camera::Data {
    troupe_msgs::camera::Data {
        width: 2,
        height: 1,
        bpp,
        format,
        fdiv: 0,
        compression: troupe_msgs::camera::COMPRESS_RAW,
        image: image.to_vec(),
    }
}

#[test]
fn camera_images_are_images_in_the_camera_s_frame() {
    use troupe_msgs::camera::*;
    let cam = dev(Interface::Camera, 0);
    let mut t = Translator::new();
    let mut one = |c: Data| t.translate(&key(&cam), 7, &AnyMsg::CameraData(c));
    let out = one(picture(FORMAT_RGB888, 24, &[1, 2, 3, 4, 5, 6])).unwrap();
    assert_eq!(
        (out[0].topic.as_str(), out[0].ty),
        ("/robot_6665/camera_0", Type::Image)
    );
    let m: Image = decode(&out[0]);
    assert_eq!(m.header.frame_id, "robot_6665/camera_0");
    assert_eq!(
        (m.width, m.height, m.step, m.encoding.as_str()),
        (2, 1, 6, "rgb8")
    );
    assert_eq!(m.data, [1, 2, 3, 4, 5, 6]);
    // Player's MONO16 is in network byte order; ROS's here little-endian.
    let m: Image = decode(&one(picture(FORMAT_MONO16, 16, &[1, 2, 3, 4])).unwrap()[0]);
    assert_eq!(
        (m.encoding.as_str(), m.step, m.is_bigendian),
        ("mono16", 4, 0)
    );
    assert_eq!(m.data, [2, 1, 4, 3]);
    // RGB565: pure red and pure blue widened to 8 bits a channel.
    let m: Image = decode(&one(picture(FORMAT_RGB565, 16, &[0x00, 0xF8, 0x1F, 0x00])).unwrap()[0]);
    assert_eq!(m.data, [255, 0, 0, 0, 0, 255]);
    let m: Image = decode(&one(picture(FORMAT_RGB888, 32, &[1, 2, 3, 0, 4, 5, 6, 0])).unwrap()[0]);
    assert_eq!(m.data, [1, 2, 3, 4, 5, 6]);
    let jpeg = Data {
        compression: COMPRESS_JPEG,
        ..picture(FORMAT_RGB888, 24, &[0xFF, 0xD8, 0xFF])
    };
    let out = one(jpeg).unwrap();
    assert_eq!(out[0].ty, Type::CompressedImage);
    let m: CompressedImage = decode(&out[0]);
    assert_eq!(
        (m.format.as_str(), m.data.as_slice()),
        ("jpeg", &[0xFF, 0xD8, 0xFF][..])
    );
    // Too few bytes for the size, or a format Player does not define: no
    // ROS 2 form (the recorder writes them as they are).
    assert!(one(picture(FORMAT_RGB888, 24, &[1, 2, 3])).is_none());
    assert!(one(picture(9, 24, &[0; 6])).is_none());
}

#[test]
fn readings_follow_ros_rules() {
    let s = back::laser_scan(&LaserScan {
        range_min: 0.1,
        range_max: 10.0,
        ranges: vec![f32::INFINITY, f32::NAN, f32::NEG_INFINITY, 0.05, 12.0, 4.0],
        ..Default::default()
    });
    assert_eq!(s.ranges, vec![10.0, 0.0, 0.0, 0.0, 10.0, 4.0]);
}
