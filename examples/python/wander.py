"""Lesson 1: wander the simple world on the sonar ring, in the native API."""

import math

import troupe
from lesson import args

a = args(__doc__)
client = troupe.connect(a.connect)
robot = client.robot(a.port)
base, sonar = robot.position2d(0), robot.ranger(0)
bearings = [p["yaw"] for p in sonar.geometry()["element_poses"]]
print(f"{len(bearings)} sonars; wandering")

base.enable(True)
sonar.read()
t0 = last = sonar.stamp
while not a.seconds or sonar.stamp - t0 < a.seconds:
    sonar.read()
    ranges = sonar.ranges
    # Slow down and turn away from the nearest obstacle ahead.
    ahead = [r for r, b in zip(ranges, bearings) if abs(b) < math.pi / 3]
    left = min((r for r, b in zip(ranges, bearings) if 0 < b < math.pi / 2), default=5.0)
    right = min((r for r, b in zip(ranges, bearings) if -math.pi / 2 < b < 0), default=5.0)
    near = min(ahead, default=5.0)
    speed = 0.0 if near < 0.5 else min(0.4, 0.4 * (near - 0.5))
    turn = 0.0 if near > 1.2 else (0.8 if left > right else -0.8)
    base.set_speed(speed, turn)
    if sonar.stamp - last >= 1.0:
        last = sonar.stamp
        x, y, yaw = base.pose
        print(f"t {last - t0:6.1f} s  at ({x:6.2f}, {y:6.2f}) facing {math.degrees(yaw):4.0f} deg"
              f"  speed {speed:.2f}{'  STALLED' if base.stall else ''}")
base.stop()
