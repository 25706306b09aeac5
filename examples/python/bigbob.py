"""Lesson 10: Bigbob wanders the yard, steers to the colour blobs it sees and zaps the trash it reaches."""

import math

import troupe
from lesson import Wanderer, args

ITEMS = "orange1,orange2,orange3,orange4,carton1,carton2,carton3,carton4"
a = args(__doc__, name="bob1", items=ITEMS)
client = troupe.connect(a.connect)
robot = client.robot(a.port)
bob = Wanderer(robot, 0, 0)
beam, eyes, sim = robot.ranger(1), robot.blobfinder(0), robot.simulation(0)
gap = beam.config()["max_range"]

client.read()
t0 = robot.data_time
left = a.items.split(",")
total = len(left)
while left and (not a.seconds or robot.data_time - t0 < a.seconds):
    client.read()
    t = robot.data_time - t0
    if len(beam.ranges) and min(beam.ranges) < gap - 0.01:
        # Something between the teeth: zap the nearest item if it is close.
        bob.base.stop()
        me = sim.get_pose2d(a.name)
        d, item = min((math.hypot(p.x - me.x, p.y - me.y), i)
                      for i, p in ((i, sim.get_pose2d(i)) for i in left))
        if d < 1.0:
            left.remove(item)
            sim.set_pose2d(item, -100.0, -100.0, 0.0)
            print(f"t {t:5.1f} s  zapped {item} ({d:.2f} m from my centre); {len(left)} to go")
        continue
    if eyes.blobs:
        blob = max(eyes.blobs, key=lambda b: b["area"])
        half = max(eyes.width, 2) / 2
        off = (half - blob["x"]) / half  # +1 left edge, -1 right edge
        bob.base.set_speed(0.3 * max(1 - abs(off), 0.2), 0.8 * off)
        continue
    bob.step()
bob.base.stop()
print(f"zapped {total - len(left)} of {total} in {robot.data_time - t0:.1f} s")
