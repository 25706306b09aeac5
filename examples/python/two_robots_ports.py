"""Lesson 7: two robots on two ports (6665 and 6666), one client each, both wandering."""

import troupe
from lesson import Wanderer, args

a = args(__doc__)
client = troupe.connect(a.connect)
robots = [Wanderer(client.robot(port)) for port in (a.port, a.port + 1)]
robots[0].sonar.read()
t0 = last = robots[0].sonar.stamp
while not a.seconds or robots[0].sonar.stamp - t0 < a.seconds:
    client.read()
    for r in robots:
        r.step()
    now = robots[0].sonar.stamp
    if now - last >= 1.0:
        last = now
        print(f"t {now - t0:5.1f} s  " + "   ".join(
            f"robot {r.base.robot.port} at ({r.base.x:6.2f}, {r.base.y:6.2f})" for r in robots))
for r in robots:
    r.base.stop()
