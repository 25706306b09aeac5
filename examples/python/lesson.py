"""What every Python lesson takes on its command line, as the Rust lessons do."""

import argparse


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
