"""Lesson 9: drive up to a box, grip it and drag it back, in Player's own API."""

import math

from playerc import *
from lesson import args

a = args(__doc__, back=1.5)
c = playerc_client(None, a.connect or "localhost", a.port)
if c.connect() != 0:
    raise playerc_error_str()
base, gripper = playerc_position2d(c, 0), playerc_gripper(c, 0)
for proxy in (base, gripper):
    if proxy.subscribe(PLAYERC_OPEN_MODE) != 0:
        raise playerc_error_str()


def read():
    if c.read() is None:
        raise playerc_error_str()


gripper.open_cmd()
base.enable(1)
print("approaching with the paddles open")
base.set_cmd_vel(0.15, 0.0, 0.0, 1)
while gripper.beams == 0:
    read()
base.set_cmd_vel(0.0, 0.0, 0.0, 1)
print("beams %s broken at (%.2f, %.2f): closing" % (format(gripper.beams, "#04b"), base.px, base.py))

gripper.close_cmd()
moving = False
while gripper.state != PLAYER_GRIPPER_STATE_CLOSED or gripper.beams == 0:
    read()
    moving |= gripper.state == PLAYER_GRIPPER_STATE_MOVING
print("holding it: closed%s, beams %#04x" % (" after moving" if moving else "", gripper.beams))

x0, y0 = base.px, base.py
base.set_cmd_vel(-0.2, 0.0, 0.0, 1)
while math.hypot(base.px - x0, base.py - y0) < a.back:
    read()
base.set_cmd_vel(0.0, 0.0, 0.0, 1)
print("dragged it %.2f m back to (%.2f, %.2f)" % (math.hypot(base.px - x0, base.py - y0), base.px, base.py))
c.disconnect()
