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
    nearest = [l for l in out.splitlines() if l.startswith("nearest ")]
    assert nearest, out
    metres = float(nearest[0].split()[1])
    assert 0 < metres <= 8.0, out


def test_goto_arrives(launch):
    stack = launch("simple.cfg", ["6665:position2d:0", "6665:simulation:0"], speedup=5)
    sim = stack.client.robot(6665).simulation(0)
    start = sim.get_pose2d("r0")
    out = run(stack, "goto.py", "--x", "2", "--y", "1", "--yaw", "90")
    # (2, 1) and 90 degrees in the odometry frame, which starts at r0's start pose.
    s, c = math.sin(start.yaw), math.cos(start.yaw)
    want = (start.x + 2 * c - s, start.y + 2 * s + c, start.yaw + math.pi / 2)
    end = sim.get_pose2d("r0")
    assert out.splitlines()[-1].startswith("arrived after"), out
    assert math.hypot(end.x - want[0], end.y - want[1]) < 0.15, (end, want, out)


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


def wanders_both(launch, cfg, lesson, devices):
    stack = launch(cfg, devices + ["6665:simulation:0"], speedup=5)
    sim = stack.client.robot(6665).simulation(0)
    starts = [sim.get_pose2d(n) for n in ("r0", "r1")]
    out = run(stack, lesson, "--for", "20")
    for name, start in zip(("r0", "r1"), starts):
        end = sim.get_pose2d(name)
        assert math.hypot(end.x - start.x, end.y - start.y) > 1.0, (name, start, end, out)


def test_two_robots_on_two_ports_both_wander(launch):
    wanders_both(launch, "two_ports.cfg", "two_robots_ports.py", ["6665:position2d:0", "6666:position2d:0"])


def test_two_robots_on_one_port_both_wander(launch):
    wanders_both(launch, "two_index.cfg", "two_robots_index.py", ["6665:position2d:0", "6665:position2d:1"])


def test_gripper_drags_the_box_back(launch):
    stack = launch("gripper.cfg", ["6665:gripper:0", "6665:position2d:0", "6665:simulation:0"], speedup=5)
    sim = stack.client.robot(6665).simulation(0)
    before = sim.get_pose2d("box")
    out = run(stack, "gripper.py", "--back", "1.5")
    # It saw the paddles move, then close (as the Rust lesson checks).
    assert "holding it: closed after moving" in out, out
    # As Stage's: the box held is at 0 0 0 on the gripper.
    held = sim.get_pose2d("box")
    assert (held.x, held.y, held.yaw) == (0.0, 0.0, 0.0), held
    # Let go: the box is where it was dragged to.
    gripper = stack.client.robot(6665).gripper(0)
    gripper.open()
    while gripper.read().state == "closed":
        pass
    after = sim.get_pose2d("box")
    assert before.x - after.x > 1.3 and abs(after.y - before.y) < 0.1, (before, after, out)


def test_bigbob_zaps_the_trash(launch):
    stack = launch("bigbob.cfg", ["6665:blobfinder:0", "6665:ranger:1", "6665:simulation:0"], speedup=10)
    out = run(stack, "bigbob.py", "--for", "300", timeout=120)
    zapped = int(out.splitlines()[-1].split()[1])
    sim = stack.client.robot(6665).simulation(0)
    gone = sum(sim.get_pose2d(i).x < -50 for i in
               ("orange1", "orange2", "orange3", "orange4", "carton1", "carton2", "carton3", "carton4"))
    assert zapped == gone and gone >= 6, out
