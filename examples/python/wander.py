"""Lesson 1: wander the simple world on the sonar ring, in the native API."""

import math

import troupe
from lesson import Wanderer, args

a = args(__doc__)
client = troupe.connect(a.connect)
bob = Wanderer(client.robot(a.port))
print(f"{len(bob.bearings)} sonars; wandering")

bob.sonar.read()
t0 = last = bob.sonar.stamp
while not a.seconds or bob.sonar.stamp - t0 < a.seconds:
    bob.sonar.read()
    bob.step()
    if bob.sonar.stamp - last >= 1.0:
        last = bob.sonar.stamp
        x, y, yaw = bob.base.pose
        print(f"t {last - t0:6.1f} s  at ({x:6.2f}, {y:6.2f}) facing {math.degrees(yaw):4.0f} deg"
              f"{'  STALLED' if bob.base.stall else ''}")
bob.base.stop()
