"""Lesson 2: drive to a pose on odometry with a proportional controller, in the native API."""

import math

import troupe
from lesson import args

a = args(__doc__, x=2.0, y=0.0)
client = troupe.connect(a.connect)
base = client.robot(a.port).position2d(0)
base.enable(True)
base.read()
start = base.pose
print(f"from ({start.x:.2f}, {start.y:.2f}) to ({a.x:.2f}, {a.y:.2f})")
while True:
    base.read()
    x, y, yaw = base.pose
    dist = math.hypot(a.x - x, a.y - y)
    if dist < 0.1:
        break
    heading = math.atan2(a.y - y, a.x - x)
    err = math.atan2(math.sin(heading - yaw), math.cos(heading - yaw))
    base.set_speed(min(0.4, dist) if abs(err) < 0.5 else 0.0, max(-1.0, min(1.0, 1.5 * err)))
base.stop()
print(f"arrived at ({base.x:.2f}, {base.y:.2f})")
