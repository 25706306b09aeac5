"""`troupe foxglove` as Foxglove meets it: a client speaking the Foxglove WebSocket protocol (its
published spec, foxglove.websocket.v1, which the Foxglove SDK negotiates under its new name
foxglove.sdk.v1) over the `websockets` library, decoding with Foxglove's own protobuf schemas; and
`--format foxglove` recordings, read with the ecosystem's reader (mcap-protobuf-support)."""

import json
import re
import signal
import struct
import subprocess
import time

import mcap.reader as mcap_reader
import mcap_protobuf.decoder as protobuf_decoder
import numpy as np
import pytest
import websockets.sync.client as ws
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.Grid_pb2 import Grid
from foxglove_schemas_protobuf.LaserScan_pb2 import LaserScan
from foxglove_schemas_protobuf.PosesInFrame_pb2 import PosesInFrame
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

MESSAGE_DATA, TIME = 0x01, 0x02


def test_foxglove_shows_the_fleet_and_its_teleop_drives_a_robot(launch, odometry_moves):
    # The server as `troupe launch --foxglove` runs it beside the stack: `troupe foxglove`.
    stack = launch("nav.cfg", ["6665:laser:0", "6665:position2d:0", "6665:map:0", "6665:simulation:0",
                               "6665:localize:0", "6665:planner:0"], args=["--foxglove=127.0.0.1:0"])
    robot = stack.client.robot(6665)
    laser, pos, sim = robot.laser(0), robot.position2d(0), robot.simulation(0)
    grid = robot.map(0).get_map()
    url = re.match(r"ws://\S+", stack.line("troupe foxglove: ")).group(0)
    with ws.connect(url, subprotocols=["foxglove.sdk.v1", "foxglove.websocket.v1"], open_timeout=10) as c:
        info = json.loads(c.recv(timeout=10))
        assert info["op"] == "serverInfo", info
        assert {"clientPublish", "time"} <= set(info["capabilities"]), info
        assert "json" in info.get("supportedEncodings", []), info

        # Channels are advertised as devices publish; the laser, the map and the transforms.
        channels, times = {}, 0
        wanted = {"/robot/6665/laser/0", "/robot/6665/map/0", "/tf", "/tf_static", "/robot/6665/position2d/0",
                  "/robot/6665/simulation/0/world"}
        deadline = time.monotonic() + 30
        while not wanted <= set(channels):
            assert time.monotonic() < deadline, f"advertised: {sorted(channels)}"
            m = c.recv(timeout=10)
            if isinstance(m, str) and json.loads(m)["op"] == "advertise":
                channels.update({ch["topic"]: ch for ch in json.loads(m)["channels"]})
            elif isinstance(m, bytes) and m[0] == TIME:
                times += 1
        scan_ch, map_ch = channels["/robot/6665/laser/0"], channels["/robot/6665/map/0"]
        assert (scan_ch["schemaName"], scan_ch["encoding"]) == ("foxglove.LaserScan", "protobuf")
        assert (map_ch["schemaName"], channels["/robot/6665/position2d/0"]["schemaName"]) == (
            "foxglove.Grid", "foxglove.PoseInFrame")
        assert channels["/tf"]["schemaName"] == channels["/tf_static"]["schemaName"] == "foxglove.FrameTransforms"
        world_ch = channels["/robot/6665/simulation/0/world"]
        assert world_ch["schemaName"] == "foxglove.SceneUpdate"
        json_topics = [t for t, ch in channels.items() if ch["encoding"] == "json"]
        assert any(t.startswith("/robot/6665/ranger/0/") for t in json_topics), json_topics

        # The map, the sensors' places and the world's walls were published before this
        # client came: they are latched, given to it as it subscribes.
        subscriptions = {1: scan_ch["id"], 2: map_ch["id"], 3: channels["/tf_static"]["id"], 4: world_ch["id"]}
        c.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": i, "channelId": ch} for i, ch in subscriptions.items()]}))
        got, refused = {}, set()
        deadline = time.monotonic() + 30
        while len(got) < len(subscriptions) or times == 0:
            assert time.monotonic() < deadline, f"got {sorted(got)}, {times} times"
            m = c.recv(timeout=10)
            # The SDK sends a channel's advertisement before it registers the channel for the
            # client (foxglove 0.30, connected_client.rs): a subscription that follows at once
            # can be answered "Unknown channel ID", the channel being known a moment later.
            # A client then subscribes again, once, as this one does.
            if isinstance(m, str) and json.loads(m)["op"] == "advertise":
                # Channels that come meanwhile (the planner's path) are kept for later.
                channels.update({ch["topic"]: ch for ch in json.loads(m)["channels"]})
            elif isinstance(m, str) and json.loads(m).get("op") == "status":
                said = json.loads(m)["message"]
                unknown = [i for i, ch in subscriptions.items() if said == f"Unknown channel ID: {ch}"]
                assert unknown and not refused & set(unknown), said
                refused |= set(unknown)
                c.send(json.dumps({"op": "subscribe", "subscriptions": [
                    {"id": i, "channelId": subscriptions[i]} for i in unknown]}))
            elif isinstance(m, bytes) and m[0] == MESSAGE_DATA:
                sub, _ = struct.unpack_from("<IQ", m, 1)
                got[sub] = m[13:]
            elif isinstance(m, bytes) and m[0] == TIME:
                times += 1
        scan = LaserScan()
        scan.ParseFromString(got[1])
        laser.read(timeout=10)
        assert len(scan.ranges) == len(laser.ranges) > 100
        assert scan.frame_id == "robot_6665/laser_0"
        assert scan.start_angle == np.float32(laser.min_angle)
        assert max(scan.ranges) <= laser.max_range + 1e-6
        g = Grid()
        g.ParseFromString(got[2])
        assert (g.column_count, len(g.data)) == (grid.width, grid.width * grid.height)
        assert g.cell_size.x == np.float32(grid.resolution) and g.frame_id == "map"
        cells = np.frombuffer(g.data, dtype=np.int8).reshape(grid.height, grid.width)
        assert np.array_equal(cells == 100, grid.cells > 0) and np.array_equal(cells == 0, grid.cells < 0)

        fixed = FrameTransforms()
        fixed.ParseFromString(got[3])
        edges = {(t.parent_frame_id, t.child_frame_id) for t in fixed.transforms}
        assert ("robot_6665/base_link", "robot_6665/laser_0") in edges, edges

        # The world's still models (walls, furniture) as Foxglove's 3D panel draws them.
        world = SceneUpdate()
        world.ParseFromString(got[4])
        assert world.entities and all(e.frame_id == "map" and e.lines for e in world.entities)

        # The teleop panel's way: advertise a channel, publish a Twist in JSON.
        c.send(json.dumps({"op": "advertise", "channels": [{
            "id": 7, "topic": "/robot/6665/position2d/0/cmd_vel", "encoding": "json",
            "schemaName": "geometry_msgs/msg/Twist"}]}))
        start = sim.get_pose2d("r0")
        twist = {"linear": {"x": 0.3, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}
        c.send(struct.pack("<BI", MESSAGE_DATA, 7) + json.dumps(twist).encode())
        odometry_moves(pos, 0.2, timeout=10)
        twist["linear"]["x"] = 0.0
        c.send(struct.pack("<BI", MESSAGE_DATA, 7) + json.dumps(twist).encode())
        moved = sim.get_pose2d("r0")
        assert np.hypot(moved.x - start.x, moved.y - start.y) > 0.2, (start, moved)

        # A goal published from the 3D panel: wavefront plans, and its path is drawn.
        c.send(json.dumps({"op": "advertise", "channels": [{
            "id": 9, "topic": "/robot/6665/planner/0/goal", "encoding": "json",
            "schemaName": "geometry_msgs/msg/PoseStamped"}]}))
        goal = (5.0, 0.0)
        c.send(struct.pack("<BI", MESSAGE_DATA, 9) + json.dumps({"header": {"frame_id": "map"}, "pose": {
            "position": {"x": goal[0], "y": goal[1], "z": 0}, "orientation": {"w": 1}}}).encode())
        path, near_goal = None, False
        if "/robot/6665/planner/0/path" in channels:
            c.send(json.dumps({"op": "subscribe", "subscriptions": [
                {"id": 10, "channelId": channels["/robot/6665/planner/0/path"]["id"]}]}))
        deadline = time.monotonic() + 30
        while not near_goal:
            assert time.monotonic() < deadline, f"no path to {goal}: advertised {sorted(channels)}"
            m = c.recv(timeout=10)
            if isinstance(m, str) and json.loads(m)["op"] == "advertise":
                for ch in json.loads(m)["channels"]:
                    channels[ch["topic"]] = ch
                    if ch["topic"] == "/robot/6665/planner/0/path":
                        assert ch["schemaName"] == "foxglove.PosesInFrame"
                        c.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 10, "channelId": ch["id"]}]}))
            elif isinstance(m, str) and json.loads(m).get("op") == "status":
                # Subscribed before the channel was registered (see above): again.
                c.send(json.dumps({"op": "subscribe", "subscriptions": [
                    {"id": 10, "channelId": channels["/robot/6665/planner/0/path"]["id"]}]}))
            elif isinstance(m, bytes) and m[0] == MESSAGE_DATA and struct.unpack_from("<I", m, 1)[0] == 10:
                # The path before the goal comes first (latched), then the new one.
                path = PosesInFrame()
                path.ParseFromString(m[13:])
                last = path.poses[-1].position if path.poses else None
                near_goal = last is not None and np.hypot(last.x - goal[0], last.y - goal[1]) < 0.5
        assert path.frame_id == "map" and len(path.poses) > 1, path

        # The 3D panel's pose estimate (a PoseWithCovarianceStamped) re-initialises amcl there.
        c.send(json.dumps({"op": "advertise", "channels": [{
            "id": 8, "topic": "/robot/6665/localize/0/set_pose", "encoding": "json",
            "schemaName": "geometry_msgs/msg/PoseWithCovarianceStamped"}]}))
        there = (moved.x + 1.5, moved.y)
        estimates = robot.localize(0).stream(timeout=10)
        c.send(struct.pack("<BI", MESSAGE_DATA, 8) + json.dumps({"header": {"frame_id": "map"}, "pose": {
            "pose": {"position": {"x": there[0], "y": there[1], "z": 0}, "orientation": {"w": 1}},
            "covariance": [0] * 36}}).encode())
        near = None
        for sample in estimates:
            mean = sample.data["hypoths"][0]["mean"] if sample.data.get("hypoths") else None
            if mean and np.hypot(mean["x"] - there[0], mean["y"] - there[1]) < 0.5:
                near = mean
                break
        assert near is not None, f"no estimate near {there}"
    stack.stop()
    assert stack.proc.returncode == 0, stack.errors
    assert not [e for e in stack.errors if "left out" in e], stack.errors


def test_a_classic_client_of_foxglove_websocket_v1_decodes_a_laser_scan(launch):
    # Lichtblick, older Foxglove Studio and @foxglove/ws-protocol offer only the classic name.
    stack = launch("simple.cfg", ["6665:laser:0"], args=["--foxglove=127.0.0.1:0"])
    url = re.match(r"ws://\S+", stack.line("troupe foxglove: ")).group(0)
    with ws.connect(url, subprotocols=["foxglove.websocket.v1"], open_timeout=10) as c:
        assert c.subprotocol == "foxglove.websocket.v1"
        info = json.loads(c.recv(timeout=10))
        assert info["op"] == "serverInfo", info
        scan_ch, deadline = None, time.monotonic() + 30
        while scan_ch is None:
            assert time.monotonic() < deadline, "no laser channel advertised"
            m = c.recv(timeout=10)
            if isinstance(m, str) and json.loads(m)["op"] == "advertise":
                scan_ch = next((ch for ch in json.loads(m)["channels"]
                                if ch["topic"] == "/robot/6665/laser/0"), None)
        assert scan_ch["schemaName"] == "foxglove.LaserScan"
        subscribe = json.dumps({"op": "subscribe", "subscriptions": [{"id": 7, "channelId": scan_ch["id"]}]})
        c.send(subscribe)
        data, again, deadline = None, True, time.monotonic() + 30
        while data is None:
            assert time.monotonic() < deadline, "no scan came"
            m = c.recv(timeout=10)
            if isinstance(m, str) and json.loads(m).get("op") == "status" and again:
                # Advertised before registered (see the test above): subscribe once more.
                again = False
                c.send(subscribe)
            elif isinstance(m, bytes) and m[0] == MESSAGE_DATA and struct.unpack_from("<I", m, 1)[0] == 7:
                data = m[13:]
        scan = LaserScan()
        scan.ParseFromString(data)
        assert len(scan.ranges) > 100 and scan.frame_id == "robot_6665/laser_0"


def foxglove_messages(path):
    """(topic, schema name, decoded message or JSON object, log_time) of every message."""
    factory, out = protobuf_decoder.DecoderFactory(), []
    with open(path, "rb") as f:
        for schema, channel, message in mcap_reader.make_reader(f).iter_messages(log_time_order=False):
            if channel.message_encoding == "json":
                assert schema.encoding == "jsonschema"
                out.append((channel.topic, schema.name, json.loads(message.data), message.log_time))
                continue
            assert (channel.message_encoding, schema.encoding) == ("protobuf", "protobuf")
            decoded = factory.decoder_for(channel.message_encoding, schema)(message.data)
            out.append((channel.topic, schema.name, decoded, message.log_time))
    return out


def test_a_recording_reads_as_foxglove_in_the_ecosystem_s_reader(launch, tmp_path):
    stack = launch("nav.cfg", ["6665:laser:0", "6665:position2d:0", "6665:map:0", "6665:simulation:0"])
    robot = stack.client.robot(6665)
    grid = robot.map(0).get_map()
    own, live = tmp_path / "run.mcap", tmp_path / "live.mcap"
    recorders = [stack.record(own), stack.record(live, "--format", "foxglove")]
    laser = robot.laser(0)
    for _ in range(15):
        laser.read(timeout=10)
    _, live_summary = recorders[1].stop()
    recorders[0].stop()
    assert "foxglove.LaserScan" in live_summary, live_summary

    export = stack.run("log", "export", str(own), "--format", "foxglove", "-o", str(tmp_path / "fox.mcap"))
    assert export.returncode == 0, export.stderr
    assert "-> foxglove.LaserScan" in export.stderr and "-> JSON" in export.stderr, export.stderr
    samples = [json.loads(line) for line in stack.run("log", "export", str(own)).stdout.splitlines()]

    for path in (tmp_path / "fox.mcap", live):
        msgs = foxglove_messages(path)
        kinds = {(t, ty) for t, ty, _, _ in msgs}
        assert {("/robot/6665/laser/0", "foxglove.LaserScan"), ("/robot/6665/position2d/0", "foxglove.PoseInFrame"),
                ("/robot/6665/map/0", "foxglove.Grid"), ("/tf", "foxglove.FrameTransforms"),
                ("/tf_static", "foxglove.FrameTransforms"),
                ("/robot/6665/simulation/0/world", "foxglove.SceneUpdate")} <= kinds, kinds
        g = next(m for _, ty, m, _ in msgs if ty == "foxglove.Grid")
        cells = np.frombuffer(g.data, dtype=np.int8).reshape(grid.height, grid.width)
        assert np.array_equal(cells == 100, grid.cells > 0) and np.array_equal(cells == 0, grid.cells < 0)
        assert g.cell_size.x == pytest.approx(grid.resolution)
        edges = {(t.parent_frame_id, t.child_frame_id)
                 for _, ty, m, _ in msgs if ty == "foxglove.FrameTransforms" for t in m.transforms}
        assert {("robot_6665/odom", "robot_6665/base_link"),
                ("robot_6665/base_link", "robot_6665/laser_0")} <= edges, edges

    # The export carries the samples' own values: every scan's ranges, stamp for stamp.
    msgs = foxglove_messages(tmp_path / "fox.mcap")
    scans = [m for t, ty, m, _ in msgs if (t, ty) == ("/robot/6665/laser/0", "foxglove.LaserScan")]
    laser_samples = [s for s in samples if s["key"] == "robot/6665/laser/0" and "LaserScan" in s["msg"]]
    assert len(scans) == len(laser_samples) >= 10
    for scan, sample in zip(scans, laser_samples):
        want = sample["msg"]["LaserScan"]
        assert np.array_equal(np.array(scan.ranges, dtype=np.float32), np.array(want["ranges"], dtype=np.float32))
        assert scan.start_angle == pytest.approx(want["min_angle"])
        assert scan.timestamp.seconds + scan.timestamp.nanos * 1e-9 == pytest.approx(sample["stamp"], abs=1e-9)
