"""Lesson 4: fetch the map and draw it in the terminal, in the native API (numpy when installed)."""

import troupe
from lesson import args

a = args(__doc__, index=0, columns=72)
m = troupe.connect(a.connect).robot(a.port).map(a.index).get_map()
print(f"{m.width} x {m.height} cells of {m.resolution} m, origin ({m.origin.x:.2f}, {m.origin.y:.2f})")
step = max(1, m.width // a.columns)
occupied = free = 0
for row in range(m.height - 1, -1, -step):
    line = ""
    for col in range(0, m.width, step):
        c = m.cell(col, row)
        line += "#" if c > 0 else ("." if c < 0 else " ")
        occupied += c > 0
        free += c < 0
    print(line)
print(f"{occupied} occupied and {free} free cells drawn")
