"""Lesson 3: the laser's geometry and a scan, in Player's own API (as Player's Python examples)."""

from playerc import *
from lesson import args

a = args(__doc__)
c = playerc_client(None, a.connect or "localhost", a.port)
if c.connect() != 0:
    raise playerc_error_str()
laser = playerc_laser(c, 0)
if laser.subscribe(PLAYERC_OPEN_MODE) != 0:
    raise playerc_error_str()
while c.read() != laser.info.id:
    pass
print("%d beams from %.3f to %.3f rad, every %.4f rad, max range %.1f m"
      % (laser.scan_count, laser.scan[0][1], laser.scan[-1][1], laser.scan_res, laser.max_range))
nearest = min(range(laser.scan_count), key=lambda i: laser.ranges[i])
print("nearest %.2f m at %.1f deg" % (laser.ranges[nearest], laser.scan[nearest][1] * 57.29578))
laser.unsubscribe()
c.disconnect()
