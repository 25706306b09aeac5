#!/usr/bin/env python3
"""Draws loop.png, the floor of worlds/loop.world: one long loop.

A corridor 2.4 m wide runs round a 33.6 m x 13.6 m block of offices, inside
a 40 m x 20 m building (800 x 400 pixels of 0.05 m, the world centred on
(0, 0)): 104 m round its middle. Doorways are recessed into both walls at uneven
spacings and a few pillars stand in the corridor, as in a real building,
so no stretch of corridor looks like another; the robot that drives round
comes back to where it started from the other side. Run it from anywhere
to redraw the PNG:

    python3 worlds/bitmaps/loop.py
"""
import os

from png import gray_png

W_M, H_M = 40.0, 20.0
RES = 0.05
T = 0.8   # outer wall thickness (a doorway is recessed into it)
C = 2.4   # corridor width
D = 0.4   # how deep a doorway is recessed

OUT = (-W_M / 2, -H_M / 2, W_M / 2, H_M / 2)
IN = (OUT[0] + T + C, OUT[1] + T + C, OUT[2] - T - C, OUT[3] - T - C)

# (x0, y0, x1, y1) in metres.
WALLS = [
    # The building's outer walls.
    (OUT[0], OUT[1], OUT[2], OUT[1] + T), (OUT[0], OUT[3] - T, OUT[2], OUT[3]),
    (OUT[0], OUT[1], OUT[0] + T, OUT[3]), (OUT[2] - T, OUT[1], OUT[2], OUT[3]),
    # The block the corridor runs round.
    IN,
    # Pillars in the corridor, against the outer wall.
    (-12.0, OUT[1] + T, -11.6, OUT[1] + T + 0.4),
    (7.0, OUT[3] - T - 0.5, 7.5, OUT[3] - T),
    (OUT[2] - T - 0.4, 2.0, OUT[2] - T, 2.6),
]

# Doorways: (side, centre along the side, width); a recess D deep cut into
# the wall. Sides: "s", "n" (x along), "w", "e" (y along); "is", "in",
# "iw", "ie" cut into the block.
DOORS = [
    ("s", -15.0, 1.0), ("s", -3.5, 1.6), ("s", 9.0, 1.0),
    ("n", -9.0, 1.0), ("n", 1.0, 2.0), ("n", 14.5, 1.0),
    ("w", -2.0, 1.2), ("e", -5.0, 1.0),
    ("is", -10.0, 1.0), ("is", 4.0, 1.0), ("is", 12.0, 2.2),
    ("in", -13.0, 1.4), ("in", -2.0, 1.0), ("in", 8.5, 1.0),
    ("iw", 1.5, 1.0), ("ie", -2.5, 1.6),
]


def recess(side, c, w):
    """The rectangle of floor a doorway cuts (white)."""
    h = w / 2
    if side == "s":
        return (c - h, OUT[1] + T - D, c + h, OUT[1] + T)
    if side == "n":
        return (c - h, OUT[3] - T, c + h, OUT[3] - T + D)
    if side == "w":
        return (OUT[0] + T - D, c - h, OUT[0] + T, c + h)
    if side == "e":
        return (OUT[2] - T, c - h, OUT[2] - T + D, c + h)
    if side == "is":
        return (c - h, IN[1], c + h, IN[1] + D)
    if side == "in":
        return (c - h, IN[3] - D, c + h, IN[3])
    if side == "iw":
        return (IN[0], c - h, IN[0] + D, c + h)
    return (IN[2] - D, c - h, IN[2], c + h)


def draw():
    cols, rows = int(round(W_M / RES)), int(round(H_M / RES))
    img = [[255] * cols for _ in range(rows)]

    def fill(rect, v):
        x0, y0, x1, y1 = rect
        # Pixel (col, row) covers x in [col, col+1) * RES - W/2; row 0 is the top.
        c0, c1 = int((x0 + W_M / 2) / RES + 1e-9), int((x1 + W_M / 2) / RES - 1e-9)
        r0, r1 = int((H_M / 2 - y1) / RES + 1e-9), int((H_M / 2 - y0) / RES - 1e-9)
        for r in range(max(r0, 0), min(r1, rows - 1) + 1):
            for c in range(max(c0, 0), min(c1, cols - 1) + 1):
                img[r][c] = v

    for rect in WALLS:
        fill(rect, 0)
    for door in DOORS:
        fill(recess(*door), 255)
    return cols, rows, img


if __name__ == "__main__":
    out = os.path.join(os.path.dirname(os.path.abspath(__file__)), "loop.png")
    with open(out, "wb") as f:
        f.write(gray_png(draw()[-1]))
    print(out)
