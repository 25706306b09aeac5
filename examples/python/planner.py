"""Lesson 5: give wavefront a goal and follow it to arrival, in Player's own API."""

from playerc import *
from lesson import args

a = args(__doc__, x=5.0, y=0.0)
c = playerc_client(None, a.connect or "localhost", a.port)
if c.connect() != 0:
    raise playerc_error_str()
planner = playerc_planner(c, 0)
if planner.subscribe(PLAYERC_OPEN_MODE) != 0:
    raise playerc_error_str()
if planner.set_cmd_pose(a.x, a.y, 0.0) != 0:
    raise playerc_error_str()
announced = False
while True:
    if c.read() is None:
        raise playerc_error_str()
    if planner.path_valid and not announced and planner.get_waypoints() == 0:
        print("a path of %d waypoints to (%.2f, %.2f)" % (planner.waypoint_count, planner.gx, planner.gy))
        announced = True
    if announced and planner.path_done:
        break
print("arrived at (%.2f, %.2f)" % (planner.px, planner.py))
c.disconnect()
