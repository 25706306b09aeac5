"""Lesson 2: the base's own position control (Player's GoTo), in the native API."""

import math

import troupe
from lesson import args

a = args(__doc__, x=2.0, y=0.0, yaw=0.0, epsilon=0.1)
client = troupe.connect(a.connect)
base = client.robot(a.port).position2d(0)
size = base.geometry()["size"]
print(f"a base {size['length']:.2f} x {size['width']:.2f} m; to ({a.x:.2f}, {a.y:.2f}) facing {a.yaw:.0f} deg")
base.enable(True)
base.go_to(a.x, a.y, math.radians(a.yaw))
t0 = base.read().stamp
while math.hypot(a.x - base.x, a.y - base.y) > a.epsilon:
    base.read()
print(f"arrived after {base.stamp - t0:.1f} s at ({base.x:.2f}, {base.y:.2f})")
