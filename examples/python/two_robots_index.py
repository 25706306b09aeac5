"""Lesson 8: two robots on one port, told apart by device index (position2d:0 and :1)."""

import troupe
from lesson import Wanderer, args

a = args(__doc__)
client = troupe.connect(a.connect)
robot = client.robot(a.port)
robots = [Wanderer(robot, 0, 0), Wanderer(robot, 1, 1)]
robots[0].sonar.read()
t0 = last = robot.data_time
while not a.seconds or robot.data_time - t0 < a.seconds:
    client.read()
    for r in robots:
        r.step()
    if robot.data_time - last >= 1.0:
        last = robot.data_time
        print(f"t {last - t0:5.1f} s  " + "   ".join(
            f"position2d:{i} at ({r.base.x:6.2f}, {r.base.y:6.2f})" for i, r in enumerate(robots)))
for r in robots:
    r.base.stop()
