"""Each Python lesson, run as a user runs it, against the stack its Rust twin uses."""

import math
import pathlib
import subprocess
import sys

HERE = pathlib.Path(__file__).resolve().parent


def run(stack, lesson, *args, timeout=90):
    out = subprocess.run([sys.executable, str(HERE / lesson), "--connect", stack.endpoint, *args],
                         env=stack.env(), capture_output=True, text=True, timeout=timeout)
    assert out.returncode == 0, out.stdout + out.stderr
    return out.stdout


def test_wander_roams(launch):
    stack = launch("simple.cfg", ["6665:position2d:0", "6665:ranger:0", "6665:simulation:0"])
    sim = stack.client.robot(6665).simulation(0)
    before = sim.get_pose2d("r0")
    out = run(stack, "wander.py", "--for", "20")
    after = sim.get_pose2d("r0")
    assert out.startswith("16 sonars; wandering"), out
    assert math.hypot(after.x - before.x, after.y - before.y) > 1.0, out


def test_laser_prints_geometry(launch):
    stack = launch("simple.cfg", ["6665:laser:0"])
    out = run(stack, "laser.py")
    assert out.startswith("180 beams from -1.571 to 1.553 rad"), out
    assert "nearest" in out


def test_goto_arrives(launch):
    stack = launch("simple.cfg", ["6665:position2d:0", "6665:simulation:0"], speedup=5)
    sim = stack.client.robot(6665).simulation(0)
    start = sim.get_pose2d("r0")
    out = run(stack, "goto.py", "--x", "2", "--y", "1")
    # (2, 1) in the odometry frame, which starts at r0's start pose.
    s, c = math.sin(start.yaw), math.cos(start.yaw)
    want = (start.x + 2 * c - s, start.y + 2 * s + c)
    end = sim.get_pose2d("r0")
    assert out.splitlines()[-1].startswith("arrived at"), out
    assert math.hypot(end.x - want[0], end.y - want[1]) < 0.2, (end, want, out)


def test_map_draws_the_office(launch):
    stack = launch("map.cfg", ["6665:map:0"])
    out = run(stack, "map.py")
    assert "#" in out and "." in out
    occupied = int(out.splitlines()[-1].split()[0])
    assert occupied > 100, out


def test_planner_and_localize_on_the_nav_stack(launch):
    stack = launch("nav.cfg", ["6665:planner:0", "6665:localize:0", "6665:simulation:0"], speedup=8)
    out = run(stack, "localize.py", "--for", "3")
    error = float(out.splitlines()[-1].split()[2])
    assert error < 0.5, out
    out = run(stack, "planner.py", "--x", "5", "--y", "0", timeout=120)
    assert out.startswith("a path of"), out
    end = stack.client.robot(6665).simulation(0).get_pose2d("r0")
    assert math.hypot(end.x - 5.0, end.y) < 0.6, out
