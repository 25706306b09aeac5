"""Recordings others read: `troupe record --format ros2` and `troupe log export --format ros2`,
decoded with the ecosystem's own reader (mcap-ros2-support), against what Troupe itself saw."""

import collections
import json
import subprocess

import mcap.reader as mcap_reader  # mcap-ros2-support, which .ci/run installs
import mcap_ros2.decoder as ros2_decoder
import numpy as np
import pytest
from rosbags.rosbag2 import Reader as Rosbag2Reader  # rosbags, which .ci/run installs
from rosbags.typesys import Stores, get_typestore

# Jazzy's definitions, as Troupe writes them (its Range has `variance`).
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


def ros2_messages(path):
    """(topic, type, decoded message or JSON object, publish_time) of every message, in file order."""
    factory, decoders, out = ros2_decoder.DecoderFactory(), {}, []
    with open(path, "rb") as f:
        reader = mcap_reader.make_reader(f)
        assert reader.get_header().profile == "ros2"
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if channel.message_encoding == "json":
                assert schema.encoding == "jsonschema"
                out.append((channel.topic, schema.name, json.loads(message.data), message.publish_time))
                continue
            assert (channel.message_encoding, schema.encoding) == ("cdr", "ros2msg")
            if schema.id not in decoders:
                decoders[schema.id] = factory.decoder_for("cdr", schema)
            out.append((channel.topic, schema.name, decoders[schema.id](message.data), message.publish_time))
    return out


def test_a_recording_reads_as_ros2_in_the_ecosystem_s_reader(launch, tmp_path):
    stack = launch("nav.cfg", ["6665:laser:0", "6665:position2d:0", "6665:map:0", "6665:localize:0"])
    robot = stack.client.robot(6665)
    grid = robot.map(0).get_map()

    # Both at once: Troupe's own format (exported after) and ROS 2 live.
    own, live, live_bag = tmp_path / "run.mcap", tmp_path / "live.mcap", tmp_path / "live_bag"
    recorders = [stack.record(own), stack.record(live, "--format", "ros2"), stack.record(live_bag, "--rosbag2")]
    laser = robot.laser(0)
    for _ in range(15):
        laser.read(timeout=10)
    recorders[2].stop()
    _, live_summary = recorders[1].stop()
    recorders[0].stop()
    assert "sensor_msgs/msg/LaserScan" in live_summary, live_summary

    export = stack.run("log", "export", str(own), "--format", "ros2", "-o", str(tmp_path / "bag.mcap"))
    assert export.returncode == 0, export.stderr
    assert "-> sensor_msgs/msg/LaserScan" in export.stderr and "-> JSON" in export.stderr, export.stderr
    samples = [json.loads(line) for line in
               stack.run("log", "export", str(own)).stdout.splitlines()]

    for path in (tmp_path / "bag.mcap", live):
        msgs = ros2_messages(path)
        kinds = collections.Counter((t, ty) for t, ty, _, _ in msgs)
        scans = [m for t, ty, m, _ in msgs if (t, ty) == ("/robot_6665/laser_0", "sensor_msgs/msg/LaserScan")]
        odoms = [m for t, ty, m, _ in msgs if (t, ty) == ("/robot_6665/position2d_0", "nav_msgs/msg/Odometry")]
        grids = [m for _, ty, m, _ in msgs if ty == "nav_msgs/msg/OccupancyGrid"]
        assert len(scans) >= 10 and len(odoms) >= 5, kinds
        assert kinds[("/clock", "rosgraph_msgs/msg/Clock")] > 0, kinds

        # The map, as ROS has it: 0 free, 100 occupied, -1 unknown, row 0 at the origin.
        assert len(grids) == 1, kinds
        g = grids[0]
        assert (g.info.width, g.info.height) == (grid.width, grid.height)
        assert g.info.resolution == pytest.approx(grid.resolution)
        assert (g.info.origin.position.x, g.info.origin.position.y) == pytest.approx((grid.origin.x, grid.origin.y))
        want = np.select([grid.cells < 0, grid.cells > 0], [0, 100], -1).astype(np.int8).ravel()
        assert np.array_equal(np.array(g.data, dtype=np.int8), want)
        assert g.header.frame_id == "map"

        # One TF tree: map -> odom (amcl), odom -> base_link (odometry), base_link -> laser (geometry).
        edges = {(tf.header.frame_id, tf.child_frame_id)
                 for t, ty, m, _ in msgs if ty == "tf2_msgs/msg/TFMessage" for tf in m.transforms}
        assert {("map", "robot_6665/odom"), ("robot_6665/odom", "robot_6665/base_link"),
                ("robot_6665/base_link", "robot_6665/laser_0")} <= edges, edges
        assert all(s.header.frame_id == "robot_6665/laser_0" for s in scans)

        # Nothing is dropped in silence: what has no ROS 2 form is JSON, on a topic of its own kind.
        json_topics = {t for t, _, m, _ in msgs if isinstance(m, dict)}
        assert "/robot_6665/simulation_0/poses" in json_topics, json_topics

    # The export carries the samples' own values: every scan's ranges, every pose, stamp for stamp.
    msgs = ros2_messages(tmp_path / "bag.mcap")
    scans = [m for t, ty, m, _ in msgs if (t, ty) == ("/robot_6665/laser_0", "sensor_msgs/msg/LaserScan")]
    odoms = [m for t, ty, m, _ in msgs if (t, ty) == ("/robot_6665/position2d_0", "nav_msgs/msg/Odometry")]
    laser_samples = [s for s in samples if s["key"] == "robot/6665/laser/0" and "LaserScan" in s["msg"]]
    odom_samples = [s for s in samples if s["key"] == "robot/6665/position2d/0"]
    assert len(scans) == len(laser_samples) and len(odoms) == len(odom_samples)
    for scan, sample in zip(scans, laser_samples):
        want = sample["msg"]["LaserScan"]
        assert np.array_equal(np.array(scan.ranges, dtype=np.float32), np.array(want["ranges"], dtype=np.float32))
        assert scan.angle_min == pytest.approx(want["min_angle"])
        assert scan.header.stamp.sec + scan.header.stamp.nanosec * 1e-9 == pytest.approx(sample["stamp"], abs=1e-9)
    for odom, sample in zip(odoms, odom_samples):
        pose = sample["msg"]["Position2dData"]["pose"]
        q = odom.pose.pose.orientation
        yaw = np.arctan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
        assert (odom.pose.pose.position.x, odom.pose.pose.position.y) == pytest.approx((pose["x"], pose["y"]), abs=1e-9)
        assert abs(np.angle(np.exp(1j * (yaw - pose["yaw"])))) < 1e-9

    # As a rosbag2 directory (metadata.yaml beside the MCAP), read by rosbags, a reader that
    # starts from the metadata, as `ros2 bag info` does, and takes CDR only.
    export = stack.run("log", "export", str(own), "--rosbag2", "-o", str(tmp_path / "bag"))
    assert export.returncode == 0, export.stderr
    for bag in (tmp_path / "bag", live_bag):
        with Rosbag2Reader(bag) as r:
            types = {c.topic: c.msgtype for c in r.connections}
            assert types["/robot_6665/laser_0"] == "sensor_msgs/msg/LaserScan", types
            assert types["/robot_6665/simulation_0/poses"] == "std_msgs/msg/String", types
            counted = collections.Counter()
            bag_scans, poses = [], []
            for c, _, raw in r.messages():
                counted[c.topic] += 1
                m = TYPESTORE.deserialize_cdr(raw, c.msgtype)
                if c.topic == "/robot_6665/laser_0":
                    bag_scans.append(m)
                elif c.topic == "/robot_6665/simulation_0/poses":
                    poses.append(json.loads(m.data))
            assert counted == {c.topic: c.msgcount for c in r.connections}
            assert r.message_count == sum(counted.values())
            assert len(bag_scans) >= 10 and poses and "poses" in poses[0], poses[:1]
    # The export's scans are the samples'.
    with Rosbag2Reader(tmp_path / "bag") as r:
        laser = [c for c in r.connections if c.topic == "/robot_6665/laser_0"]
        bag_scans = [TYPESTORE.deserialize_cdr(raw, c.msgtype) for c, _, raw in r.messages(connections=laser)]
    assert len(bag_scans) == len(laser_samples)
    for scan, sample in zip(bag_scans, laser_samples):
        assert np.array_equal(scan.ranges, np.array(sample["msg"]["LaserScan"]["ranges"], dtype=np.float32))


# What a ROS 2 tool writes: the types' definitions as ROS 2 ships them (comments left out).
HEADER = "builtin_interfaces/Time stamp\nstring frame_id\n"
TIME = "int32 sec\nuint32 nanosec\n"
SEP = "=" * 80 + "\n"
ROS_DEFS = {
    "sensor_msgs/msg/LaserScan": (
        "std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\nfloat32 angle_increment\n"
        "float32 time_increment\nfloat32 scan_time\nfloat32 range_min\nfloat32 range_max\n"
        "float32[] ranges\nfloat32[] intensities\n"
        + SEP + "MSG: std_msgs/Header\n" + HEADER + SEP + "MSG: builtin_interfaces/Time\n" + TIME),
    "nav_msgs/msg/Odometry": (
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\n"
        "geometry_msgs/TwistWithCovariance twist\n"
        + SEP + "MSG: std_msgs/Header\n" + HEADER + SEP + "MSG: builtin_interfaces/Time\n" + TIME
        + SEP + "MSG: geometry_msgs/PoseWithCovariance\nPose pose\nfloat64[36] covariance\n"
        + SEP + "MSG: geometry_msgs/Pose\nPoint position\nQuaternion orientation\n"
        + SEP + "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n"
        + SEP + "MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
        + SEP + "MSG: geometry_msgs/TwistWithCovariance\nTwist twist\nfloat64[36] covariance\n"
        + SEP + "MSG: geometry_msgs/Twist\nVector3 linear\nVector3 angular\n"
        + SEP + "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n"),
    "rosgraph_msgs/msg/Clock": "builtin_interfaces/Time clock\n" + SEP + "MSG: builtin_interfaces/Time\n" + TIME,
}


def test_a_ros2_bag_written_by_ros_tools_plays_into_amcl(launch, tmp_path, odometry_moves):
    from mcap_ros2.writer import Writer

    # A run to bag: r0 driven through the office while its laser, odometry and clock are recorded.
    live = launch("nav.cfg", ["6665:position2d:0", "6665:laser:0", "6665:simulation:0"])
    robot = live.client.robot(6665)
    pos, sim = robot.position2d(0), robot.simulation(0)
    start = sim.get_pose2d("r0")
    recorder = live.record(tmp_path / "run.mcap", "--format", "ros2",
                        "robot/6665/laser/0", "robot/6665/position2d/0", "sim/clock")
    pos.set_speed(0.3, 0.12)
    odometry_moves(pos, 1.2, timeout=20)
    pos.stop()
    truth = sim.get_pose2d("r0")
    recorder.stop()
    assert np.hypot(truth.x - start.x, truth.y - start.y) > 1.2

    # The same run as a ROS 2 robot would bag it: /scan, /odom, /clock, written by ROS's own writer.
    bag = tmp_path / "ros.mcap"
    renamed = {"/robot_6665/laser_0": "/scan", "/robot_6665/position2d_0": "/odom", "/clock": "/clock"}
    written = collections.Counter()
    with open(bag, "wb") as f:
        w = Writer(f)
        schemas = {name: w.register_msgdef(name, text) for name, text in ROS_DEFS.items()}
        for topic, ty, msg, stamp in ros2_messages(tmp_path / "run.mcap"):
            if topic in renamed and ty in schemas:
                w.write_message(renamed[topic], schemas[ty], msg, log_time=stamp, publish_time=stamp)
                written[renamed[topic]] += 1
        w.finish()
    assert written["/scan"] > 20 and written["/odom"] > 20 and written["/clock"] > 20, written

    # amcl alone, on the same map, fed by nothing but the bag.
    loc = launch("localize.cfg", ["6665:map:0"],
                 args=["--external", "position2d:0", "--external", "laser:0", "--sim-time"])
    play = subprocess.Popen(
        [loc.bin, "--namespace", loc.namespace, "--connect", loc.endpoint, "play", str(bag),
         "--remap", "/scan=robot/6665/laser/0", "--remap", "/odom=robot/6665/position2d/0"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    loc.client.wait_for("6665:localize:0", timeout=30)
    est = loc.client.robot(6665).localize(0)
    out, err = play.communicate(timeout=120)
    assert play.returncode == 0, err
    assert "left out" not in err, err
    assert out.startswith("played "), out
    # The bag's every scan and pose reached amcl: it followed r0 from where it started to where it stopped.
    fix = est.pose
    assert fix is not None
    assert np.hypot(fix.x - truth.x, fix.y - truth.y) < 0.35, (fix, truth)
