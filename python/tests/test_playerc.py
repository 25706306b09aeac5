"""`from playerc import *`, in the style of Player's own Python tests and examples
(client_libs/libplayerc/bindings/python/test, examples/python/playercpy_example.py)."""

import math

import pytest

from playerc import *


@pytest.fixture
def connected(monkeypatch):
    """`connected(stack)`: a playerc client of robot 6665 on the stack, as Player's tests open one."""

    def connect(stack):
        monkeypatch.setenv("TROUPE_NAMESPACE", stack.namespace)
        c = playerc_client(None, stack.endpoint, 6665)
        if c.connect() != 0:
            raise playerc_error_str()
        return c

    return connect


def test_device_list_laser_loop_and_turning(launch, connected):
    stack = launch("simple.cfg", ["6665:position2d:0", "6665:laser:0", "6665:simulation:0"])
    c = connected(stack)

    # test.py: the device list.
    if c.get_devlist() != 0:
        raise playerc_error_str()
    listed = {(d.addr.robot, playerc_lookup_name(d.addr.interf), d.addr.index): d.drivername
              for d in c.devinfos[:c.devinfo_count]}
    assert listed[(6665, "laser", 0)] == "rangertolaser"
    assert listed[(6665, "position2d", 0)] == "stage"

    # test_laser.py: read until the laser's data came, ten times.
    laser = playerc_laser(c, 0)
    if laser.subscribe(PLAYERC_OPEN_MODE) != 0:
        raise playerc_error_str()
    stamps = []
    for i in range(10):
        while 1:
            id = c.read()
            assert id is not None, playerc_error_str()
            if id == laser.info.id:
                break
        stamps.append(laser.info.datatime)
        # tr_laser: 180 beams a degree apart from -pi/2, 8 m at most.
        assert laser.scan_count == 180 and laser.scan_start == pytest.approx(-math.pi / 2)
        assert laser.scan_res == pytest.approx(math.pi / 180) and laser.max_range == 8.0
        assert all(0 < r <= 8.0 for r in laser.ranges[:laser.scan_count])
    assert stamps == sorted(stamps) and stamps[-1] > stamps[0]
    assert laser.info.drivername == "rangertolaser"

    # playercpy_example.py: geometry, then turn CCW at 20 deg/s.
    p = playerc_position2d(c, 0)
    if p.subscribe(PLAYERC_OPEN_MODE) != 0:
        raise playerc_error_str()
    if p.get_geom() != 0:
        raise playerc_error_str()
    assert p.size[0] > 0 and p.size[1] > 0
    if laser.get_geom() != 0:
        raise playerc_error_str()
    p.set_cmd_vel(0.0, 0.0, 20.0 * math.pi / 180.0, 1)
    turned = 0.0
    for i in range(300):
        if c.read() is None:
            raise playerc_error_str()
        turned = max(turned, abs(p.va))
        if turned > 0.3:
            break
    p.set_cmd_vel(0.0, 0.0, 0.0, 1)
    assert turned == pytest.approx(20.0 * math.pi / 180.0, abs=0.02)

    sim = playerc_simulation(c, 0)
    assert sim.subscribe(PLAYERC_OPEN_MODE) == 0
    result, x, y, a = sim.get_pose2d("r0")
    # It turned in place, where simple.world put it.
    assert result == 0 and (x, y) == pytest.approx((-6.0, -6.0), abs=0.05)
    result, *_ = sim.get_pose2d("nope")
    assert result == -1 and "nope" in str(playerc_error_str())

    p.unsubscribe()
    laser.unsubscribe()
    c.disconnect()


def test_errors_are_codes_and_raisable_strings(launch, connected):
    stack = launch("simple.cfg", ["6665:position2d:0"])
    c = connected(stack)
    ghost = playerc_laser(c, 9)
    assert ghost.subscribe(PLAYERC_OPEN_MODE) == -1
    err = playerc_error_str()
    assert "6665:laser:9" in err and "live" in str(err)
    with pytest.raises(playerc_error):
        raise playerc_error_str()
    assert playerc_lookup_name(PLAYER_LASER_CODE) == "laser"
    assert playerc_lookup_name(PLAYER_POSITION2D_CODE) == "position2d"
    assert c.datamode(PLAYERC_DATAMODE_PULL) == 0 and c.datamode(99) == -1
    bad = playerc_client(None, "tcp/127.0.0.1:1", 6665)
    assert bad.connect() == -1 and "127.0.0.1:1" in str(playerc_error_str())


def test_pull_mode_brings_every_proxy_at_once(launch, connected):
    stack = launch("simple.cfg", ["6665:position2d:0", "6665:laser:0", "6665:ranger:0"])
    c = connected(stack)
    c.datamode(PLAYERC_DATAMODE_PULL)
    p, l, r = playerc_position2d(c, 0), playerc_laser(c, 0), playerc_ranger(c, 0)
    for proxy in (p, l, r):
        assert proxy.subscribe(PLAYERC_OPEN_MODE) == 0
    assert r.get_geom() == 0 and r.element_count > 0
    for _ in range(50):
        assert c.read() is not None
        if l.scan_count and r.ranges_count and p.info.datatime:
            break
    assert l.scan_count > 0 and r.ranges_count == r.element_count and p.info.datatime > 0


def test_map_localize_and_planner(launch, connected):
    stack = launch("nav.cfg", ["6665:map:0", "6665:planner:0", "6665:localize:0"], speedup=8)
    c = connected(stack)
    m = playerc_map(c, 0)
    assert m.subscribe(PLAYERC_OPEN_MODE) == 0 and m.get_map() == 0
    assert len(m.cells) == m.width * m.height and {-1, 1} <= set(m.cells)
    loc, plan = playerc_localize(c, 0), playerc_planner(c, 0)
    assert loc.subscribe(PLAYERC_OPEN_MODE) == 0 and plan.subscribe(PLAYERC_OPEN_MODE) == 0
    assert loc.get_particles() == 0 and loc.num_particles > 0
    assert plan.set_cmd_pose(loc.mean[0] + 1.0, loc.mean[1], 0.0) == 0
    for _ in range(500):
        id = c.read()
        assert id is not None, playerc_error_str()
        if id == plan.info.id and plan.path_valid:
            break
    assert plan.path_valid == 1 and plan.waypoint_count >= 1
    assert plan.get_waypoints() == 0 and len(plan.waypoints) == plan.waypoint_count
