"""Lesson 6: amcl's estimate beside the simulator's truth while the robot turns, in the native API."""

import math

import troupe
from lesson import args

a = args(__doc__)
robot = troupe.connect(a.connect).robot(a.port)
loc, sim, base = robot.localize(0), robot.simulation(0), robot.position2d(0)
base.set_speed(0.0, 0.4)
t0 = None
error = float("inf")
for sample in loc.stream(timeout=30):
    t0 = sample.stamp if t0 is None else t0
    if not loc.hypotheses:
        continue
    est, truth = loc.pose, sim.get_pose2d("r0")
    error = math.hypot(est.x - truth.x, est.y - truth.y)
    print(f"t {sample.stamp - t0:5.1f} s  estimate ({est.x:6.2f}, {est.y:6.2f})  "
          f"truth ({truth.x:6.2f}, {truth.y:6.2f})  {len(loc.hypotheses)} hypotheses  error {error:.2f} m")
    if a.seconds and sample.stamp - t0 >= a.seconds:
        break
base.stop()
print(f"final error {error:.2f} m")
