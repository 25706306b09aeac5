"""`import troupe` against launched stacks: every proxy reads, commands move the robot, errors say why."""

import math
import threading

import numpy as np
import pytest

import troupe


def test_simple_cfg_reads_every_device_and_drives(launch):
    stack = launch("simple.cfg", ["6665:position2d:0", "6665:laser:0", "6665:ranger:1", "6665:simulation:0"])
    client = stack.client
    # The listing ends when the router has answered; on a loaded machine
    # its answer once took longer than the 1 s default.
    names = {str(d): d.driver for d in client.devices(6665, timeout=10)}
    assert names["6665:laser:0"] == "rangertolaser" and names["6665:position2d:0"] == "stage", names

    robot = client.robot(6665)
    pos, laser, sonar, lranger, sim = (robot.position2d(0), robot.laser(0), robot.ranger(0),
                                       robot.ranger(1), robot.simulation(0))
    fresh = client.read(timeout=10)
    assert fresh and all(isinstance(p, troupe.Proxy) for p in fresh)

    laser.read(timeout=10)
    ranges = laser.ranges
    assert isinstance(ranges, np.ndarray) and ranges.dtype == np.float64
    beams = len(ranges)
    assert beams > 100 and 0 < ranges.min() <= ranges.max() <= laser.max_range
    # tr_laser: 180 beams over 180 degrees, the first at -pi/2.
    assert beams == 180 and laser.resolution == pytest.approx(math.pi / 180)
    assert laser.bearings[0] == pytest.approx(-math.pi / 2)
    assert laser.bearings[-1] == pytest.approx(-math.pi / 2 + 179 * math.pi / 180)
    assert laser.points.shape == (beams, 2) and laser.stamp > 0
    assert laser.geometry()["size"]["width"] > 0

    sonar.read(timeout=10)
    lranger.read(timeout=10)
    assert len(sonar.ranges) == 16 and len(lranger.ranges) == beams
    assert len(sonar.geometry()["element_poses"]) == len(sonar.ranges)

    # Drive: the odometry and the simulator both see r0 move forward.
    start, truth = pos.read().pose, sim.get_pose2d("r0")
    pos.set_speed(0.4, 0.0)
    moved = 0.0
    for sample in pos.stream(timeout=10):
        assert sample.kind == "position2d/data"
        p = sample.data["pose"]
        moved = math.hypot(p["x"] - start.x, p["y"] - start.y)
        if moved > 0.3:
            break
    pos.stop()
    assert moved > 0.3, f"r0 moved {moved} m"
    after = sim.get_pose2d("r0")
    assert math.hypot(after.x - truth.x, after.y - truth.y) > 0.25

    sim.set_pose2d("r0", truth.x, truth.y, 1.0)
    assert abs(sim.get_pose2d("r0").yaw - 1.0) < 1e-3


def test_errors_are_python_exceptions_with_the_reason(launch):
    stack = launch("simple.cfg", ["6665:simulation:0", "6665:position2d:0"])
    robot = stack.client.robot(6665)
    sim = robot.simulation(0)
    with pytest.raises(troupe.RequestRefused, match="nope"):
        sim.get_pose2d("nope")
    ghost = robot.laser(7)
    with pytest.raises(troupe.NoAnswer, match="6665:laser:7"):
        ghost.request("geom", "laser/get_geom", timeout=0.3)
    with pytest.raises(TimeoutError):
        ghost.read(timeout=0.2)
    with pytest.raises(troupe.ReadTimeout):
        stack.client.wait_for("6665:laser:7", timeout=0.2)
    with pytest.raises(ValueError, match="position2d/cmd_vel"):
        robot.position2d(0).command("vel", "position2d/cmd_vel", {"vel": 1})
    with pytest.raises(ValueError, match="interface"):
        robot.device("nosuch", 0)
    with pytest.raises(troupe.TroupeError):
        troupe.connect("tcp/127.0.0.1:1", namespace=stack.namespace)


def test_callbacks_and_streams_deliver_every_message(launch):
    stack = launch("simple.cfg", ["6665:laser:0"])
    laser = stack.client.robot(6665).laser(0)
    got, done = [], threading.Event()

    def on_scan(sample):
        got.append(sample)
        if len(got) == 5:
            done.set()

    sub = laser.on_data(on_scan)
    assert done.wait(10), f"{len(got)} callbacks"
    sub.stop()
    stamps = [s.stamp for s in got if s.kind == "laser/scan"]
    assert stamps == sorted(stamps) and len(stamps) >= 2
    streamed = [s for _, s in zip(range(4), laser.stream())]
    assert len(streamed) == 4
    # From a count taken earlier, a stream starts with what came since:
    # two steps' scans come before it is called (a step may bring two).
    before, stamp = laser.count, laser.stamp_of("laser/scan")
    for _ in range(2):
        newer = stamp
        while stamp <= newer:
            stamp = laser.read().stamp_of("laser/scan")
    first = next(s for s in laser.stream(since=before) if s.kind == "laser/scan")
    assert first.stamp < stamp, (first.stamp, stamp)


def test_map_comes_as_an_array(launch):
    stack = launch("map.cfg", ["6665:map:0"])
    m = stack.client.robot(6665).map(0).get_map()
    assert m.cells.shape == (m.height, m.width) and m.cells.dtype == np.int8
    values = set(np.unique(m.cells).tolist())
    assert {-1, 1} <= values, values
    assert m.resolution > 0 and m.cell(m.width, 0) is None


def test_nav_stack_localizes_and_plans(launch):
    stack = launch("nav.cfg", ["6665:planner:0", "6665:localize:0", "6665:simulation:0"], speedup=8)
    robot = stack.client.robot(6665)
    loc, planner, sim = robot.localize(0), robot.planner(0), robot.simulation(0)
    truth = sim.get_pose2d("r0")
    # The hypotheses amcl draws on set_pose may come before set_pose returns
    # (its answer and its data travel apart), and the robot stands still, so
    # nothing follows them: the stream starts from the count before it.
    before = loc.count
    loc.set_pose(truth.x, truth.y, truth.yaw, cov=(0.05, 0.05, 0.01, 0, 0, 0))
    est = None
    for s in loc.stream(timeout=20, since=before):
        if s.data["hypoths"]:
            est = loc.pose
            break
    assert est is not None and math.hypot(est.x - truth.x, est.y - truth.y) < 0.5, (est, truth)
    assert len(loc.particles()["particles"]) > 0

    planner.set_goal(truth.x + 1.0, truth.y, 0.0)
    # `valid` is the newest state, even one that came before set_goal returned.
    for _ in range(100):
        if planner.valid:
            break
        planner.read(timeout=20)
    assert planner.valid and planner.waypoint_count >= 1
    assert len(planner.waypoints()) == planner.waypoint_count


def test_gripper_and_blobfinder(launch):
    stack = launch("gripper.cfg", ["6665:gripper:0"])
    gripper = stack.client.robot(6665).gripper(0)
    gripper.read(timeout=10)
    assert gripper.state == "open"
    gripper.close()
    # The paddles close on nothing here: moving, then closed (Stage's).
    seen = []
    for _ in gripper.stream(timeout=10):
        if not seen or seen[-1] != gripper.state:
            seen.append(gripper.state)
        if gripper.state == "closed":
            break
    assert seen[-2:] == ["moving", "closed"], seen
    assert gripper.stored == 0
    geometry = gripper.geometry()
    assert (geometry["num_beams"], geometry["capacity"]) == (2, 0), geometry

    bob = launch("bigbob.cfg", ["6665:blobfinder:0"])
    finder = bob.client.robot(6665).blobfinder(0)
    finder.read(timeout=10)
    # bob1's camera sees at least one coloured item, inside its image and
    # its 5 m range.
    blobs = finder.blobs
    assert finder.width > 0 and blobs, blobs
    for b in blobs:
        assert 0 <= b["x"] < finder.width and 0 <= b["y"] < finder.height, b
        assert 0 < b["range"] <= 5.0 and b["area"] > 0, b


def test_without_numpy_ranges_and_maps_are_lists(launch, monkeypatch):
    stack = launch("nav.cfg", ["6665:map:0", "6665:laser:0"])
    monkeypatch.setattr(troupe, "_np", None)
    robot = stack.client.robot(6665)
    laser = robot.laser(0).read()
    assert isinstance(laser.ranges, list) and isinstance(laser.points[0], tuple)
    m = robot.map(0).get_map()
    assert isinstance(m.cells, list) and len(m.cells) == m.height and len(m.cells[0]) == m.width
    assert {-1, 1} <= {c for row in m.cells for c in row}


def test_camera_images_raw_and_jpeg_are_arrays(launch):
    stack = launch("camera.cfg", ["6665:camera:0", "6665:camera:1"])
    robot = stack.client.robot(6665)
    raw, jpeg = robot.camera(0), robot.camera(1)
    raw.read(timeout=10)
    jpeg.read(timeout=10)
    assert (raw.width, raw.height, raw.bpp, raw.format) == (160, 120, 24, troupe.Camera.FORMAT_RGB888)
    assert raw.compression == troupe.Camera.COMPRESS_RAW and len(raw.image) == 160 * 120 * 3
    # A frame's bytes reach Python as bytes, not as a list of ints.
    assert isinstance(raw.latest("camera/data")["image"], bytes)
    assert jpeg.compression == troupe.Camera.COMPRESS_JPEG and jpeg.image[:2] == b"\xff\xd8"
    a, b = raw.pixels, jpeg.pixels
    assert a.shape == b.shape == (120, 160, 3) and a.dtype == np.uint8
    # Row 0 is the top: Stage's background above, its white floor below.
    assert tuple(a[0, 80]) == (179, 179, 204) and tuple(a[119, 80]) == (255, 255, 255)
    # Straight ahead and below the horizon, the low green box; to the right, the tall blue one.
    assert tuple(a[70, 80]) == (0, 255, 0)
    assert tuple(a[60, 140]) == (0, 0, 255)
    # The JPEG of an image close to it (quality 0.9; they may be a step apart).
    assert np.abs(a.astype(int) - b.astype(int)).mean() < 12
