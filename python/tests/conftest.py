"""Stacks for the tests: `troupe launch` of a cfg under worlds/, in a namespace of its own.

The `troupe` binary is $TROUPE_BIN (tests/integration/python.rs sets it to
the build under test), else target/debug/troupe.
"""

import os
import math
import pathlib
import queue
import signal
import subprocess
import threading
import uuid

import pytest

import troupe

ROOT = pathlib.Path(__file__).resolve().parents[2]
WORLDS = ROOT / "worlds"


def troupe_bin() -> str:
    return os.environ.get("TROUPE_BIN") or str(ROOT / "target" / "debug" / "troupe")


class Stack:
    """A launched cfg: its router's endpoint, its namespace, and a client on it."""

    def __init__(self, cfg: str, devices, speedup=None, args=()):
        self.namespace = f"py-{pathlib.Path(cfg).stem}-{uuid.uuid4().hex[:8]}"
        self.bin = troupe_bin()
        extra = args
        args = [troupe_bin(), "--namespace", self.namespace, "launch", str(WORLDS / cfg),
                "--listen", "tcp/127.0.0.1:0", "--no-bridge"]
        if speedup is not None:
            args += ["--speedup", str(speedup)]
        args += list(extra)
        self.proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.lines: "queue.Queue[str]" = queue.Queue()
        self.seen: list = []
        self.recorders: list = []
        self.errors: list = []
        self.pumps = [threading.Thread(target=self._pump, args=(self.proc.stdout, self.lines.put), daemon=True),
                      threading.Thread(target=self._pump, args=(self.proc.stderr, self.errors.append), daemon=True)]
        for t in self.pumps:
            t.start()
        self.endpoint = self._endpoint()
        self.client = troupe.connect(self.endpoint, namespace=self.namespace)
        self.client.wait_for(*devices, timeout=30)

    @staticmethod
    def _pump(stream, sink):
        for line in stream:
            sink(line.rstrip("\n"))

    def _endpoint(self) -> str:
        return self.line("troupe launch: router listening on ").split()[0]

    def line(self, prefix: str, timeout: float = 30) -> str:
        """The rest of the first line the launcher printed (or prints within `timeout` s) that
        starts with `prefix`."""
        while True:
            for line in self.seen:
                if line.startswith(prefix):
                    return line[len(prefix):]
            try:
                self.seen.append(self.lines.get(timeout=timeout))
            except queue.Empty:
                raise AssertionError(f"no `{prefix}` line from the launcher: {self.errors}")

    def env(self) -> dict:
        """The environment a program run against this stack gets."""
        return dict(os.environ, TROUPE_NAMESPACE=self.namespace)

    def record(self, path, *flags):
        """`troupe record -o PATH FLAGS…` against this stack, returned once its subscriptions are
        in place."""
        recorder = Recorder(self, path, *flags)
        self.recorders.append(recorder)
        return recorder

    def run(self, *args):
        """An offline command of this stack's binary (`log export …`)."""
        return subprocess.run([self.bin, *args], capture_output=True, text=True, timeout=120)

    def stop(self):
        """Stops the stack as Ctrl-C does (once: again is a no-op); then `errors` holds the whole
        of its log."""
        for r in self.recorders:
            # One a failed test left running.
            if r.proc.poll() is None:
                r.proc.kill()
                r.proc.communicate()
        if self.proc.poll() is not None:
            return
        self.client.close()
        self.proc.send_signal(signal.SIGINT)
        try:
            self.proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        for t in self.pumps:
            t.join(timeout=10)


class Recorder:
    """`troupe record` against a stack, started once its subscriptions are in place."""

    def __init__(self, stack, path, *flags):
        self.proc = subprocess.Popen(
            [stack.bin, "--namespace", stack.namespace, "--connect", stack.endpoint, "record", "-o", str(path),
             *flags], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        first = self.proc.stdout.readline()
        if not first.startswith("troupe record:"):
            self.proc.kill()
            _, err = self.proc.communicate()
            raise AssertionError(f"troupe record did not start: {first!r} {err}")

    def stop(self):
        """Stops it as Ctrl-C does; its (stdout, stderr)."""
        self.proc.send_signal(signal.SIGINT)
        out, err = self.proc.communicate(timeout=60)
        assert self.proc.returncode == 0, (out, err)
        return out, err


@pytest.fixture
def launch():
    """`launch(cfg, devices, speedup=None, args=())`: a Stack, stopped after the test."""
    stacks = []

    def start(cfg, devices, speedup=None, args=()):
        stack = Stack(cfg, devices, speedup, args)
        stacks.append(stack)
        return stack

    yield start
    for s in stacks:
        s.stop()


def _odometry_moves(pos, metres: float, timeout: float) -> float:
    """Reads a position2d until its odometry has moved `metres` from the first pose it reads
    (or no sample came for `timeout` s); returns how far it moved."""
    first, moved = None, 0.0
    for sample in pos.stream(timeout=timeout):
        p = sample.data["pose"]
        first = first or p
        moved = math.hypot(p["x"] - first["x"], p["y"] - first["y"])
        if moved > metres:
            break
    return moved


@pytest.fixture
def odometry_moves():
    """`odometry_moves(pos, metres, timeout)`: a fixture, since a test module cannot import this
    conftest by name when pytest also collects examples/python."""
    return _odometry_moves
