"""Troupe for Python: the robots of a Zenoh network, as proxies with their latest data.

    import troupe

    client = troupe.connect()            # the local router, as the `troupe` CLI
    robot = client.robot(6665)
    pos, laser = robot.position2d(0), robot.laser(0)
    for _ in range(100):
        client.read()                    # waits for new data on any proxy
        turn = 0.5 if laser.ranges.min() < 0.5 else 0.0
        pos.set_speed(0.3, turn)

Every proxy keeps its device's latest data as attributes, updated in the
background; ``client.read()`` and ``proxy.read()`` wait for new data,
``proxy.stream()`` iterates over every message and ``proxy.on_data(fn)``
calls ``fn`` with each. Commands and requests are methods; a device that
refuses a request raises ``RequestRefused`` with its reason. Ranges, points
and maps are numpy arrays when numpy is installed, lists otherwise.

The package talks Zenoh directly, like the CLI: no bridge, no TCP hop.
Player's own Python API is the sibling module ``playerc``.
"""

from __future__ import annotations

import math
import os
import threading
import time
from typing import Any, Callable, Dict, Iterator, List, NamedTuple, Optional, Sequence, Tuple, Union

from . import _native
from ._native import NoAnswer, ReadTimeout, RequestRefused, TroupeError

try:
    import numpy as _np
except ImportError:  # numpy is optional: lists then
    _np = None

__all__ = [
    "connect", "Client", "Robot", "Proxy", "Sample", "DeviceInfo", "Pose",
    "Position2d", "Laser", "Ranger", "Sonar", "Map", "Localize", "Planner",
    "Simulation", "Blobfinder", "Fiducial", "Gripper", "Bumper", "Ir", "Gps", "Ptz",
    "Camera", "TroupeError", "RequestRefused", "NoAnswer", "ReadTimeout",
]

#: How long ``read()`` waits by default, in seconds (libplayerc++'s Read gives up after 10 s too).
READ_TIMEOUT = 10.0
#: How long a request waits for its answer, in seconds (libplayerc's 5 s).
REQUEST_TIMEOUT = 5.0


def _floats(values: Sequence[float]):
    return _np.asarray(values, dtype=_np.float64) if _np is not None else list(values)


class Pose(NamedTuple):
    """A planar pose: metres, metres, radians (counter-clockwise)."""

    x: float
    y: float
    yaw: float


def _pose(d: Optional[Dict[str, float]]) -> Pose:
    return Pose(d["x"], d["y"], d["yaw"]) if d else Pose(0.0, 0.0, 0.0)


def _pose_dict(x: float, y: float, yaw: float) -> Dict[str, float]:
    return {"x": float(x), "y": float(y), "yaw": float(yaw)}


class Sample(NamedTuple):
    """One message of a device: its kind (``laser/scan``), its stamp (s) and its fields."""

    kind: str
    stamp: float
    data: Any


class DeviceInfo(NamedTuple):
    """A live device: ``robot``, ``interface``, ``index`` and the ``driver`` providing it."""

    robot: int
    interface: str
    index: int
    driver: str

    def __str__(self) -> str:
        return f"{self.robot}:{self.interface}:{self.index}"


def connect(
    endpoint: Union[str, Sequence[str], None] = None,
    *,
    config: Optional[str] = None,
    namespace: Optional[str] = None,
) -> "Client":
    """Joins the robots' network, with the `troupe` CLI's defaults.

    ``endpoint``: the router to join (``"tcp/10.0.0.2:7447"``, or a list);
    by default the local router at tcp/127.0.0.1:7447 that ``troupe launch``
    embeds, unless ``config`` says otherwise. ``config``: a Zenoh JSON5 file,
    as ``--zenoh-config`` takes (the TLS files ``troupe fleet-keys`` writes).
    ``namespace``: the fleet's or test's namespace (default
    ``$TROUPE_NAMESPACE``, as the CLI). Raises ``TroupeError`` when no router
    answers, saying where it looked.
    """
    if isinstance(endpoint, str):
        endpoint = [endpoint]
    if namespace is None:
        namespace = os.environ.get("TROUPE_NAMESPACE") or None
    session = _native.Session(list(endpoint) if endpoint else None, config, namespace)
    return Client(session)


class Client:
    """A connection to the network: robots, their devices, and ``read()``."""

    def __init__(self, session: "_native.Session"):
        self._session = session
        self._proxies: Dict[int, "Proxy"] = {}
        self._lock = threading.Lock()

    def robot(self, port: int = 6665) -> "Robot":
        """Robot ``port`` (6665 as Player's first robot)."""
        return Robot(self, port)

    def devices(self, robot: Optional[int] = None, timeout: float = 1.0) -> List[DeviceInfo]:
        """The live devices of ``robot`` (all robots when None), as ``troupe list`` shows them."""
        return [DeviceInfo(*d) for d in self._session.devices(robot, timeout)]

    def wait_for(self, *devices: str, timeout: float = READ_TIMEOUT) -> None:
        """Waits until every device named (``"6665:laser:0"``) is live; raises
        ``ReadTimeout`` naming those that are not after ``timeout`` s."""
        self._session.wait_live(list(devices), timeout)

    def read(self, timeout: float = READ_TIMEOUT) -> List["Proxy"]:
        """Waits until some proxy got new data; returns the proxies that did.

        Raises ``ReadTimeout`` (a ``TimeoutError``) when nothing came within ``timeout`` s.
        """
        ids = self._session.wait(timeout)
        with self._lock:
            return [self._proxies[i] for i in ids if i in self._proxies]

    def _register(self, proxy: "Proxy") -> None:
        with self._lock:
            self._proxies[proxy._feed.id] = proxy

    def _forget(self, proxy: "Proxy") -> None:
        with self._lock:
            self._proxies.pop(proxy._feed.id, None)

    def close(self) -> None:
        """Leaves the network."""
        self._session.close()

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


class Robot:
    """One robot: a port of the network, and factories for its devices' proxies."""

    def __init__(self, client: Client, port: int):
        self.client = client
        self._native = client._session.robot(port)

    @property
    def port(self) -> int:
        """The robot's port."""
        return self._native.port

    @property
    def data_time(self) -> float:
        """Stamp of the newest sample any of this robot's proxies got (simulation time under Stage)."""
        return self._native.data_time

    def devices(self, timeout: float = 1.0) -> List[DeviceInfo]:
        """This robot's live devices."""
        return self.client.devices(self.port, timeout)

    def position2d(self, index: int = 0) -> "Position2d":
        return Position2d(self, index)

    def laser(self, index: int = 0) -> "Laser":
        return Laser(self, index)

    def ranger(self, index: int = 0) -> "Ranger":
        return Ranger(self, index)

    def sonar(self, index: int = 0) -> "Sonar":
        return Sonar(self, index)

    def map(self, index: int = 0) -> "Map":
        return Map(self, index)

    def localize(self, index: int = 0) -> "Localize":
        return Localize(self, index)

    def planner(self, index: int = 0) -> "Planner":
        return Planner(self, index)

    def simulation(self, index: int = 0) -> "Simulation":
        return Simulation(self, index)

    def blobfinder(self, index: int = 0) -> "Blobfinder":
        return Blobfinder(self, index)

    def fiducial(self, index: int = 0) -> "Fiducial":
        return Fiducial(self, index)

    def gripper(self, index: int = 0) -> "Gripper":
        return Gripper(self, index)

    def bumper(self, index: int = 0) -> "Bumper":
        return Bumper(self, index)

    def ir(self, index: int = 0) -> "Ir":
        return Ir(self, index)

    def gps(self, index: int = 0) -> "Gps":
        return Gps(self, index)

    def camera(self, index: int = 0) -> "Camera":
        return Camera(self, index)

    def ptz(self, index: int = 0) -> "Ptz":
        return Ptz(self, index)

    def device(self, interface: str, index: int = 0) -> "Proxy":
        """A proxy for any interface, its messages as dicts (``proxy.latest("aio/data")``)."""
        cls = _PROXIES.get(interface)
        if cls is not None:
            return cls(self, index)
        return Proxy(self, index, interface)


class Subscription:
    """A callback running on a thread of its own; ``stop()`` ends it."""

    def __init__(self, proxy: "Proxy", callback: Callable[[Sample], Any]):
        self._stop = threading.Event()
        self._thread = threading.Thread(
            target=self._run, args=(proxy, callback), daemon=True,
            name=f"troupe {proxy.device}")
        self._thread.start()

    def _run(self, proxy: "Proxy", callback: Callable[[Sample], Any]) -> None:
        after = proxy._feed.seq
        while not self._stop.is_set():
            try:
                after, kind, stamp, data = proxy._feed.next(after, 0.1)
            except ReadTimeout:
                continue
            callback(Sample(kind, stamp, data))

    def stop(self) -> None:
        """Stops the callbacks (one already running finishes)."""
        self._stop.set()
        if threading.current_thread() is not self._thread:
            self._thread.join()


class Proxy:
    """A device: its latest data, and the ways to wait for more.

    Subclasses name the interface's fields; any proxy also gives its raw
    messages: ``latest(kind)`` the newest of a kind as a dict, ``stream()``
    every message in order, ``on_data(fn)`` a callback per message.
    """

    interface = ""
    #: The kind that carries the device's data, where it sends others
    #: beside it: the first ``read()`` waits for one of these.
    data_kind: Optional[str] = None

    def __init__(self, robot: Robot, index: int = 0, interface: Optional[str] = None):
        if interface is not None:
            self.interface = interface
        self.robot = robot
        self.index = index
        self._feed = robot._native.subscribe(self.interface, index)
        self._cache: Dict[str, Tuple[int, float, Any]] = {}
        self._seen = 0
        robot.client._register(self)

    @property
    def device(self) -> str:
        """The device's address, ``6665:laser:0``."""
        return self._feed.device

    def latest(self, kind: str) -> Optional[Dict[str, Any]]:
        """The newest message of ``kind`` (``laser/scan``) as a dict, or None before the first."""
        seq, _, data = self._cache.get(kind, (0, 0.0, None))
        got = self._feed.latest(kind, seq)
        if got is not None:
            self._cache[kind] = got
            return got[2]
        return data

    def stamp_of(self, kind: str) -> float:
        """The stamp of the newest message of ``kind`` (s), 0 before the first."""
        self.latest(kind)
        return self._cache.get(kind, (0, 0.0, None))[1]

    @property
    def fresh(self) -> bool:
        """True when data arrived since the last ``read()`` of this proxy."""
        return self._feed.seq > self._seen

    @property
    def count(self) -> int:
        """Messages received so far."""
        return self._feed.seq

    def read(self, timeout: float = READ_TIMEOUT) -> "Proxy":
        """Waits for a message newer than the last read (at most ``timeout`` s); returns the proxy.

        The first read waits for the device's data itself (a ranger's ranges,
        not only its intensities), so its fields are filled when it returns.
        """
        deadline = time.monotonic() + timeout
        after, _, _, _ = self._feed.next(self._seen, timeout)
        while self._seen == 0 and self.data_kind and self.latest(self.data_kind) is None:
            after, _, _, _ = self._feed.next(after, max(0.0, deadline - time.monotonic()))
        self._seen = max(after, self._feed.seq)
        return self

    def stream(self, timeout: Optional[float] = READ_TIMEOUT,
               since: Optional[int] = None) -> Iterator[Sample]:
        """Every message from now on, in order; stops after ``timeout`` s without one
        (``None``: never). A reader more than 256 messages behind skips the oldest.

        ``since``: start after message number ``since`` instead (a ``count``
        taken before a request): what a request makes a driver publish can
        come before the request returns, and a stream begun after it would
        miss that (``n = loc.count; loc.set_pose(...); loc.stream(since=n)``).
        """
        after = self._feed.seq if since is None else since
        while True:
            try:
                after, kind, stamp, data = self._feed.next(after, 3600.0 if timeout is None else timeout)
            except ReadTimeout:
                if timeout is None:
                    continue
                return
            yield Sample(kind, stamp, data)

    def on_data(self, callback: Callable[[Sample], Any]) -> Subscription:
        """Calls ``callback(sample)`` with every message, on a thread of its own."""
        return Subscription(self, callback)

    def request(self, name: str, kind: str, payload: Any = None, timeout: float = REQUEST_TIMEOUT) -> Any:
        """Sends request ``name`` (the key's last chunk) holding message ``kind``; returns the answer's fields.

        Raises ``RequestRefused`` with the device's reason, or ``NoAnswer``.
        """
        return self.robot._native.request(self.interface, self.index, name, kind, payload, timeout)[2]

    def command(self, name: str, kind: str, payload: Any = None) -> None:
        """Sends command ``name`` holding message ``kind`` (no answer)."""
        self.robot._native.command(self.interface, self.index, name, kind, payload)

    def set_power(self, on: bool = True) -> None:
        """Player's power request (``PLAYER_REQ_POWER``)."""
        self.request("power", "common/power", {"state": bool(on)})

    def unsubscribe(self) -> None:
        """Stops this proxy's subscription; the latest data stays readable."""
        self.robot.client._forget(self)
        self._feed.close()

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.device}>"


class Position2d(Proxy):
    """A planar mobile base: odometry, velocity and position commands."""

    interface = "position2d"

    def _d(self) -> Dict[str, Any]:
        return self.latest("position2d/data") or {}

    @property
    def pose(self) -> Pose:
        """Odometric pose (x m, y m, yaw rad)."""
        return _pose(self._d().get("pose"))

    @property
    def x(self) -> float:
        return self.pose.x

    @property
    def y(self) -> float:
        return self.pose.y

    @property
    def yaw(self) -> float:
        return self.pose.yaw

    @property
    def velocity(self) -> Pose:
        """Velocity in the robot's frame: forward m/s, sideways m/s, turn rad/s."""
        return _pose(self._d().get("vel"))

    @property
    def stall(self) -> bool:
        """True when the motors are stalled (a collision in simulation)."""
        return bool(self._d().get("stall", False))

    @property
    def stamp(self) -> float:
        return self.stamp_of("position2d/data")

    def set_speed(self, forward: float, turn: float) -> None:
        """Drive forward (m/s) and turn (rad/s): libplayerc++'s SetSpeed."""
        self.set_velocity(forward, 0.0, turn)

    def set_velocity(self, x: float, y: float, yaw: float, enable: bool = True) -> None:
        """Velocity command (Player's CMD_VEL): x, y m/s and yaw rad/s in the robot's frame."""
        self.command("vel", "position2d/cmd_vel", {"vel": _pose_dict(x, y, yaw), "state": bool(enable)})

    def stop(self) -> None:
        """Velocity zero."""
        self.set_velocity(0.0, 0.0, 0.0)

    def go_to(self, x: float, y: float, yaw: float) -> None:
        """Position command (Player's CMD_POS, libplayerc++'s GoTo) in the odometric frame."""
        self.command("pos", "position2d/cmd_pos",
                     {"pos": _pose_dict(x, y, yaw), "vel": _pose_dict(0, 0, 0), "state": True})

    def enable(self, on: bool = True) -> None:
        """Turns the motors on or off (Player's MOTOR_POWER request)."""
        self.request("motor_power", "position2d/motor_power", {"state": bool(on)})

    def set_odometry(self, x: float, y: float, yaw: float) -> None:
        """Sets the odometric pose (Player's SET_ODOM)."""
        self.request("set_odom", "position2d/set_odom", {"pose": _pose_dict(x, y, yaw)})

    def reset_odometry(self) -> None:
        """Odometry back to (0, 0, 0) (Player's RESET_ODOM)."""
        self.request("reset_odom", "position2d/reset_odom")

    def geometry(self) -> Dict[str, Any]:
        """The base's pose and size in the robot's frame (``pose``, ``size``)."""
        return self.request("geom", "position2d/get_geom")


class Laser(Proxy):
    """A scanning range finder."""

    interface = "laser"

    def _scan(self) -> Dict[str, Any]:
        return self.latest("laser/scan") or {}

    @property
    def scan(self) -> Optional[Dict[str, Any]]:
        """The latest scan, all its fields, or None before the first."""
        return self.latest("laser/scan")

    @property
    def ranges(self):
        """Ranges (m), from the first beam (at ``min_angle``) counter-clockwise."""
        return _floats(self._scan().get("ranges", ()))

    @property
    def intensity(self) -> List[int]:
        """Intensity (reflector) value of each beam."""
        return list(self._scan().get("intensity", ()))

    @property
    def min_angle(self) -> float:
        return float(self._scan().get("min_angle", 0.0))

    @property
    def max_angle(self) -> float:
        return float(self._scan().get("max_angle", 0.0))

    @property
    def resolution(self) -> float:
        """Angle between beams (rad)."""
        return float(self._scan().get("resolution", 0.0))

    @property
    def max_range(self) -> float:
        return float(self._scan().get("max_range", 0.0))

    @property
    def scan_id(self) -> int:
        """The scan's number."""
        return int(self._scan().get("id", 0))

    @property
    def stamp(self) -> float:
        return self.stamp_of("laser/scan")

    @property
    def bearings(self):
        """The angle of each beam (rad)."""
        s = self._scan()
        n = len(s.get("ranges", ()))
        a, r = float(s.get("min_angle", 0.0)), float(s.get("resolution", 0.0))
        return _floats([a + i * r for i in range(n)])

    @property
    def points(self):
        """Beam ends in the laser's frame, an (n, 2) array (a list of pairs without numpy)."""
        rs, bs = self.ranges, self.bearings
        if _np is not None:
            return _np.stack([rs * _np.cos(bs), rs * _np.sin(bs)], axis=1)
        return [(r * math.cos(b), r * math.sin(b)) for r, b in zip(rs, bs)]

    def geometry(self) -> Dict[str, Any]:
        """The laser's pose and size on the robot (``pose``, ``size``)."""
        return self.request("geom", "laser/get_geom")

    def config(self) -> Dict[str, Any]:
        """The scan's configuration (angles, resolution, range, intensity)."""
        return self.request("get_config", "laser/get_config")

    def configure(self, **changes: Any) -> Dict[str, Any]:
        """Changes configuration fields (``max_range=4.0``); returns what the device applied."""
        config = self.config()
        config.update(changes)
        return self.request("set_config", "laser/set_config", {"config": config})


class Ranger(Proxy):
    """A set of range sensors (a laser or a sonar ring, Player 3's ranger)."""

    interface = "ranger"
    data_kind = "ranger/ranges"

    @property
    def ranges(self):
        """Ranges (m), one per element or beam."""
        return _floats((self.latest("ranger/ranges") or {}).get("ranges", ()))

    @property
    def intensities(self):
        return _floats((self.latest("ranger/intensities") or {}).get("intensities", ()))

    @property
    def stamp(self) -> float:
        return self.stamp_of("ranger/ranges")

    def geometry(self) -> Dict[str, Any]:
        """Pose and size of the device and of each element (``element_poses``)."""
        return self.request("geom", "ranger/get_geom")

    def config(self) -> Dict[str, Any]:
        return self.request("get_config", "ranger/get_config")


class Sonar(Proxy):
    """A sonar ring (Player's sonar interface)."""

    interface = "sonar"

    @property
    def ranges(self):
        return _floats((self.latest("sonar/ranges") or {}).get("ranges", ()))

    def geometry(self) -> Dict[str, Any]:
        """The pose of each transducer (``poses``)."""
        return self.request("geom", "sonar/get_geom")


class Map(Proxy):
    """An occupancy grid; ``get_map()`` fetches it."""

    interface = "map"

    def __init__(self, robot: Robot, index: int = 0):
        super().__init__(robot, index)
        self.width = 0
        self.height = 0
        self.resolution = 0.0
        self.origin = Pose(0.0, 0.0, 0.0)
        self.cells: Any = [] if _np is None else _np.zeros((0, 0), dtype=_np.int8)

    def get_map(self) -> "Map":
        """Fetches the whole map; ``cells[row][col]`` is -1 free, 0 unknown, +1 occupied,
        row 0 at the origin's y (a 2-D int8 array with numpy, a list of rows without)."""
        w, h, res, origin, cells = self.robot._native.map(self.index)
        self.width, self.height, self.resolution, self.origin = w, h, res, Pose(*origin)
        if _np is not None:
            self.cells = _np.frombuffer(cells, dtype=_np.int8).reshape(h, w)
        else:
            signed = [c - 256 if c > 127 else c for c in cells]
            self.cells = [signed[r * w:(r + 1) * w] for r in range(h)]
        return self

    def cell(self, col: int, row: int) -> Optional[int]:
        """Cell (col, row), None outside the map."""
        if not (0 <= col < self.width and 0 <= row < self.height):
            return None
        return int(self.cells[row][col])

    def to_world(self, col: int, row: int) -> Tuple[float, float]:
        """The centre of cell (col, row) in the world (m)."""
        return (self.origin.x + (col + 0.5) * self.resolution,
                self.origin.y + (row + 0.5) * self.resolution)


class Localize(Proxy):
    """A localizer (amcl): pose hypotheses; ``set_pose`` re-initialises it."""

    interface = "localize"

    def _h(self) -> Dict[str, Any]:
        return self.latest("localize/hypoths") or {}

    @property
    def hypotheses(self) -> List[Dict[str, Any]]:
        """Each hypothesis: ``mean`` (a Pose), ``cov`` (xx, yy, aa, xy, ya, xa), ``weight``."""
        return [{"mean": _pose(h["mean"]), "cov": list(h["cov"]), "weight": h["weight"]}
                for h in self._h().get("hypoths", ())]

    @property
    def pose(self) -> Optional[Pose]:
        """The mean of the heaviest hypothesis, None before the first."""
        hs = self._h().get("hypoths", ())
        if not hs:
            return None
        return _pose(max(hs, key=lambda h: h["weight"])["mean"])

    @property
    def pending_count(self) -> int:
        return int(self._h().get("pending_count", 0))

    @property
    def stamp(self) -> float:
        return self.stamp_of("localize/hypoths")

    def set_pose(self, x: float, y: float, yaw: float,
                 cov: Sequence[float] = (0.25, 0.25, (math.pi / 12) ** 2, 0.0, 0.0, 0.0)) -> None:
        """Re-initialises the filter around (x, y, yaw) with covariance ``cov``."""
        self.request("set_pose", "localize/set_pose",
                     {"mean": _pose_dict(x, y, yaw), "cov": [float(c) for c in cov]})

    def particles(self) -> Dict[str, Any]:
        """The particle set: ``mean``, ``variance``, ``particles`` (each ``pose``, ``weight``)."""
        return self.request("particles", "localize/get_particles")


class Planner(Proxy):
    """A path planner (wavefront): goals, the path, progress."""

    interface = "planner"

    def _s(self) -> Dict[str, Any]:
        return self.latest("planner/state") or {}

    @property
    def valid(self) -> bool:
        """True when a path to the goal exists."""
        return bool(self._s().get("valid", False))

    @property
    def done(self) -> bool:
        """True when the robot arrived."""
        return bool(self._s().get("done", False))

    @property
    def pose(self) -> Pose:
        return _pose(self._s().get("pose"))

    @property
    def goal(self) -> Pose:
        return _pose(self._s().get("goal"))

    @property
    def waypoint(self) -> Pose:
        """The waypoint being driven to."""
        return _pose(self._s().get("waypoint"))

    @property
    def waypoint_index(self) -> int:
        return int(self._s().get("waypoint_idx", -1))

    @property
    def waypoint_count(self) -> int:
        return int(self._s().get("waypoints_count", 0))

    @property
    def stamp(self) -> float:
        return self.stamp_of("planner/state")

    def set_goal(self, x: float, y: float, yaw: float) -> None:
        """Plans to (x, y, yaw) in the map's frame and drives there."""
        self.command("goal", "planner/goal", {"goal": _pose_dict(x, y, yaw)})

    def enable(self, on: bool = True) -> None:
        """Starts or stops following the path."""
        self.request("enable", "planner/enable", {"state": bool(on)})

    def waypoints(self) -> List[Pose]:
        """The path's waypoints."""
        return [_pose(w) for w in self.request("waypoints", "planner/get_waypoints")["waypoints"]]


class Simulation(Proxy):
    """The simulator: model poses and properties."""

    interface = "simulation"

    def get_pose2d(self, name: str) -> Pose:
        """Model ``name``'s pose in the world."""
        return _pose(self.request("get_pose2d", "simulation/get_pose2d", {"name": name})["pose"])

    def set_pose2d(self, name: str, x: float, y: float, yaw: float) -> None:
        """Moves model ``name``."""
        self.request("set_pose2d", "simulation/set_pose2d", {"name": name, "pose": _pose_dict(x, y, yaw)})

    def get_property(self, name: str, prop: str) -> Any:
        """A model property (``"color"``, ``"mass"``…): a number, an int, text or a colour dict."""
        value = self.request("get_property", "simulation/get_property", {"name": name, "prop": prop})["value"]
        return next(iter(value.values())) if isinstance(value, dict) else value

    def set_property(self, name: str, prop: str, value: Any) -> None:
        """Sets a model property: a float, an int, a str, or a colour dict ``{"r":…, "g":…, "b":…, "a":…}``."""
        if isinstance(value, bool) or isinstance(value, int):
            tagged: Dict[str, Any] = {"Int": int(value)}
        elif isinstance(value, float):
            tagged = {"Number": value}
        elif isinstance(value, str):
            tagged = {"Text": value}
        else:
            tagged = {"Color": dict(value)}
        self.request("set_property", "simulation/set_property", {"name": name, "prop": prop, "value": tagged})


class Blobfinder(Proxy):
    """A colour-blob tracker."""

    interface = "blobfinder"

    def _d(self) -> Dict[str, Any]:
        return self.latest("blobfinder/data") or {}

    @property
    def blobs(self) -> List[Dict[str, Any]]:
        """Each blob: ``id``, ``color``, ``area``, ``x``, ``y``, ``left``… ``range``."""
        return list(self._d().get("blobs", ()))

    @property
    def width(self) -> int:
        return int(self._d().get("width", 0))

    @property
    def height(self) -> int:
        return int(self._d().get("height", 0))


class Fiducial(Proxy):
    """A fiducial (beacon) detector."""

    interface = "fiducial"

    @property
    def fiducials(self) -> List[Dict[str, Any]]:
        """Each detection: ``id``, ``pose`` and ``upose`` (3-D, relative to the sensor)."""
        return list((self.latest("fiducial/data") or {}).get("fiducials", ()))

    def geometry(self) -> Dict[str, Any]:
        return self.request("geom", "fiducial/get_geom")


class Gripper(Proxy):
    """A gripper: open, close, what it holds."""

    interface = "gripper"

    def _d(self) -> Dict[str, Any]:
        return self.latest("gripper/data") or {}

    @property
    def state(self) -> str:
        """``"open"``, ``"closed"``, ``"moving"`` or ``"error"``."""
        return str(self._d().get("state", "Open")).lower()

    @property
    def beams(self) -> int:
        """The break beams, one bit each."""
        return int(self._d().get("beams", 0))

    @property
    def stored(self) -> int:
        """Objects held."""
        return int(self._d().get("stored", 0))

    def open(self) -> None:
        self.command("open", "gripper/open")

    def close(self) -> None:
        """Closes the paddles."""
        self.command("close", "gripper/close")

    def stop(self) -> None:
        self.command("stop", "gripper/stop")

    def geometry(self) -> Dict[str, Any]:
        return self.request("geom", "gripper/get_geom")


class Bumper(Proxy):
    """Bumpers: which are pressed."""

    interface = "bumper"

    @property
    def bumpers(self) -> List[bool]:
        return list((self.latest("bumper/data") or {}).get("bumpers", ()))

    def geometry(self) -> Dict[str, Any]:
        return self.request("geom", "bumper/get_geom")


class Ir(Proxy):
    """Infrared rangers."""

    interface = "ir"

    @property
    def ranges(self):
        return _floats((self.latest("ir/data") or {}).get("ranges", ()))

    @property
    def voltages(self):
        return _floats((self.latest("ir/data") or {}).get("voltages", ()))

    def geometry(self) -> Dict[str, Any]:
        return self.request("pose", "ir/get_geom")


class Gps(Proxy):
    """A GPS receiver: the latest fix as ``data``."""

    interface = "gps"

    @property
    def data(self) -> Optional[Dict[str, Any]]:
        return self.latest("gps/data")


class Ptz(Proxy):
    """A pan-tilt-zoom unit."""

    interface = "ptz"

    @property
    def data(self) -> Optional[Dict[str, Any]]:
        return self.latest("ptz/data")


def _int_field(kind: str, name: str, doc: str) -> Any:
    """A read-only attribute: field `name` of the latest `kind` message, as an int (0 before one)."""
    return property(lambda self: int((self.latest(kind) or {}).get(name, 0)), doc=doc)


class Camera(Proxy):
    """A camera: the latest image's fields (``width``, ``height``, ``bpp``, ``format``,
    ``compression``, ``image`` as bytes) and its ``pixels``, decompressed."""

    interface = "camera"

    #: ``format``: 8-bit grey, 16-bit grey (network byte order), RGB 5-6-5, RGB 8-8-8.
    FORMAT_MONO8, FORMAT_MONO16, FORMAT_RGB565, FORMAT_RGB888 = 1, 2, 4, 5
    #: ``compression``: raw pixels, or a JPEG file.
    COMPRESS_RAW, COMPRESS_JPEG = 0, 1

    def _d(self) -> Dict[str, Any]:
        return self.latest("camera/data") or {}

    width = _int_field("camera/data", "width", "Pixels across.")
    height = _int_field("camera/data", "height", "Pixels down.")
    bpp = _int_field("camera/data", "bpp", "Bits per pixel.")
    format = _int_field("camera/data", "format", "One of the FORMAT_ values.")
    compression = _int_field("camera/data", "compression", "COMPRESS_RAW or COMPRESS_JPEG.")

    @property
    def image(self) -> bytes:
        """The image's bytes as they came: pixels, or a JPEG file."""
        return bytes(self._d().get("image", ()))

    @property
    def pixels(self):
        """The latest image as rows from the top: a (height, width, 3) uint8 array for colour,
        (height, width) for grey (uint16 for MONO16), a JPEG decompressed first, as
        ``playerc_camera_decompress`` does. Without numpy: ``(width, height, channels,
        bytes)``. None before the first image."""
        d = self._d()
        if not d:
            return None
        w, h, data = int(d["width"]), int(d["height"]), bytes(d["image"])
        if d["compression"] == self.COMPRESS_JPEG:
            w, h, channels, data = _native.jpeg_decode(data)
            fmt, bpp = (self.FORMAT_RGB888, 24) if channels == 3 else (self.FORMAT_MONO8, 8)
        else:
            fmt, bpp = int(d["format"]), int(d["bpp"])
        if fmt == self.FORMAT_MONO16:
            channels, dtype = 1, ">u2"
        elif fmt == self.FORMAT_MONO8:
            channels, dtype = 1, "u1"
        elif fmt == self.FORMAT_RGB888:
            channels, dtype = bpp // 8, "u1"
        else:
            raise TroupeError(f"{self.device}: format {fmt} ({bpp} bits) is not converted")
        if _np is None:
            return (w, h, channels, data)
        a = _np.frombuffer(data, dtype=_np.dtype(dtype), count=w * h * channels)
        if dtype == ">u2":
            return a.astype(_np.uint16).reshape(h, w)
        a = a.reshape(h, w, channels) if channels > 1 else a.reshape(h, w)
        return a[:, :, :3] if channels == 4 else a


_PROXIES = {cls.interface: cls for cls in (
    Position2d, Laser, Ranger, Sonar, Map, Localize, Planner, Simulation,
    Blobfinder, Fiducial, Gripper, Bumper, Ir, Gps, Ptz, Camera)}
