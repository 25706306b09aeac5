#!/usr/bin/env python3
"""Draws office.png, the floor plan of Troupe's navigation worlds.

16 m x 16 m at 0.05 m per pixel (320 x 320), black walls on white, the world
centred on (0, 0). Every wall is a rectangle in metres, so the plan reads
like the world files that use it. Run it from anywhere to redraw the PNG:

    python3 worlds/bitmaps/office.py
"""
import os

from png import gray_png

SIZE_M = 16.0
RES = 0.05
T = 0.15  # wall thickness

# (x0, y0, x1, y1) in metres.
WALLS = [
    # The outer walls.
    (-8, -8, 8, -8 + T), (-8, 8 - T, 8, 8), (-8, -8, -8 + T, 8), (8 - T, -8, 8, 8),
    # The north-west room: a wall along y = 2 with two doors.
    (-8, 2, -6, 2 + T), (-4.8, 2, -1.5, 2 + T), (-0.3, 2, 2, 2 + T),
    # The east rooms: a wall along x = 2 with a door to the north-west room…
    (2, -3, 2 + T, 4), (2, 5.2, 2 + T, 8),
    # …and a wall along y = -3 with a door to the south hall.
    (2, -3, 4.5, -3 + T), (5.7, -3, 8, -3 + T),
    # Pillars in the south hall, a table in the north-west room.
    (-4.3, -4.3, -3.7, -3.7), (-0.3, -5.8, 0.3, -5.2), (4.7, -6.3, 5.3, -5.7),
    (-5.6, 4.6, -4.4, 5.4),
]


def draw():
    n = int(round(SIZE_M / RES))
    img = [[255] * n for _ in range(n)]
    for x0, y0, x1, y1 in WALLS:
        # Pixel (col, row) covers x in [col, col+1) * RES - 8; row 0 is the top (y = 8).
        c0, c1 = int((x0 + 8) / RES + 1e-9), int((x1 + 8) / RES - 1e-9)
        r0, r1 = int((8 - y1) / RES + 1e-9), int((8 - y0) / RES - 1e-9)
        for r in range(max(r0, 0), min(r1, n - 1) + 1):
            for c in range(max(c0, 0), min(c1, n - 1) + 1):
                img[r][c] = 0
    return n, img


if __name__ == "__main__":
    out = os.path.join(os.path.dirname(os.path.abspath(__file__)), "office.png")
    with open(out, "wb") as f:
        f.write(gray_png(draw()[-1]))
    print(out)
