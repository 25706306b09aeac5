"""`troupe foxglove` as Foxglove meets it: a client speaking the Foxglove WebSocket protocol (its
published spec, foxglove.websocket.v1, which the Foxglove SDK negotiates under its new name
foxglove.sdk.v1) over the `websockets` library, decoding with Foxglove's own protobuf schemas."""

import json
import re
import signal
import struct
import subprocess
import time

import numpy as np
import websockets.sync.client as ws
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.Grid_pb2 import Grid
from foxglove_schemas_protobuf.LaserScan_pb2 import LaserScan

MESSAGE_DATA, TIME = 0x01, 0x02


class Server:
    def __init__(self, stack):
        self.proc = subprocess.Popen(
            [stack.bin, "--namespace", stack.namespace, "--connect", stack.endpoint, "foxglove", "--port", "0"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        line = self.proc.stdout.readline()
        found = re.search(r"ws://\S+", line)
        assert found, (line, self.proc.stderr.read() if self.proc.poll() is not None else "")
        self.url = found.group(0)

    def stop(self):
        self.proc.send_signal(signal.SIGINT)
        _, err = self.proc.communicate(timeout=30)
        assert self.proc.returncode == 0, err
        return err


def test_foxglove_shows_the_fleet_and_its_teleop_drives_a_robot(launch, odometry_moves):
    stack = launch("nav.cfg", ["6665:laser:0", "6665:position2d:0", "6665:map:0", "6665:simulation:0"])
    robot = stack.client.robot(6665)
    laser, pos, sim = robot.laser(0), robot.position2d(0), robot.simulation(0)
    grid = robot.map(0).get_map()
    server = Server(stack)
    try:
        with ws.connect(server.url, subprotocols=["foxglove.sdk.v1", "foxglove.websocket.v1"], open_timeout=10) as c:
            info = json.loads(c.recv(timeout=10))
            assert info["op"] == "serverInfo", info
            assert {"clientPublish", "time"} <= set(info["capabilities"]), info
            assert "json" in info.get("supportedEncodings", []), info

            # Channels are advertised as devices publish; the laser, the map and the transforms.
            channels, times = {}, 0
            wanted = {"/robot/6665/laser/0", "/robot/6665/map/0", "/tf", "/tf_static", "/robot/6665/position2d/0"}
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
            json_topics = [t for t, ch in channels.items() if ch["encoding"] == "json"]
            assert "/robot/6665/simulation/0/poses" in json_topics, json_topics

            # The map and the sensors' places were published before this client came: they are
            # latched, given to it as it subscribes.
            subscriptions = {1: scan_ch["id"], 2: map_ch["id"], 3: channels["/tf_static"]["id"]}
            c.send(json.dumps({"op": "subscribe", "subscriptions": [
                {"id": i, "channelId": ch} for i, ch in subscriptions.items()]}))
            got, refused = {}, set()
            deadline = time.monotonic() + 30
            while len(got) < 3 or times == 0:
                assert time.monotonic() < deadline, f"got {sorted(got)}, {times} times"
                m = c.recv(timeout=10)
                # The SDK sends a channel's advertisement before it registers the channel for the
                # client (foxglove 0.30, connected_client.rs): a subscription that follows at once
                # can be answered "Unknown channel ID", the channel being known a moment later.
                # A client then subscribes again, once, as this one does.
                if isinstance(m, str) and json.loads(m).get("op") == "status":
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
    finally:
        err = server.stop()
    assert "left out" not in err, err
