"""What every Python lesson takes on its command line, as the Rust lessons do."""

import argparse
import math


def args(description: str, **extra) -> argparse.Namespace:
    """`--connect ENDPOINT` (default: the local router), `-p PORT` (the robot),
    `--for SECS` (simulated seconds to run, 0 = until Ctrl-C), and the lesson's own."""
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--connect", default=None, help="the router, e.g. tcp/10.0.0.2:7447")
    p.add_argument("-p", "--port", type=int, default=6665, help="the robot (Player's port)")
    p.add_argument("--for", dest="seconds", type=float, default=0.0, help="simulated seconds to run")
    for name, default in extra.items():
        p.add_argument(f"--{name}", type=type(default), default=default)
    return p.parse_args()


# The classic wander rule, as examples/lib.rs has it.
AVOID, CAUTION, CRUISE = 0.4, 0.7, 0.4


class Wanderer:
    """A base and its sonar ring (a ranger), steered by the wander rule: closer
    than CAUTION ahead, turn away (the same way until clear); closer than AVOID, stop and turn."""

    def __init__(self, robot, base: int = 0, sonar: int = 0):
        self.base, self.sonar = robot.position2d(base), robot.ranger(sonar)
        self.bearings = [p["yaw"] for p in self.sonar.geometry()["element_poses"]]
        self.turning = 0.0
        self.base.enable(True)

    def step(self) -> None:
        """Steers by the newest ranges."""
        ranges = self.sonar.ranges
        if len(ranges) != len(self.bearings):
            return  # no scan yet
        ahead, left, right = float("inf"), 0.0, 0.0
        for r, b in zip(ranges, self.bearings):
            if abs(b) <= math.radians(60):
                ahead = min(ahead, r)
            if 0 < b < math.radians(100):
                left += min(r, 3.0)
            elif -math.radians(100) < b < 0:
                right += min(r, 3.0)
        if ahead >= CAUTION:
            self.turning = 0.0
            self.base.set_speed(CRUISE, 0.0)
            return
        if self.turning == 0.0:
            self.turning = 1.0 if left >= right else -1.0
        if ahead < AVOID:
            self.base.set_speed(0.0, self.turning * math.radians(40))
        else:
            self.base.set_speed(0.1, self.turning * math.radians(20))
