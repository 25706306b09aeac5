"""Player's Python API (libplayerc's SWIG module, ``from playerc import *``) for Python 3, on Troupe.

Player's own bindings only ever built for Python 2. This module keeps their
names and behaviour so that a Player script runs once its ``print``
statements are ported:

    from playerc import *

    c = playerc_client(None, 'localhost', 6665)
    if c.connect() != 0:
        raise playerc_error_str()
    p = playerc_position2d(c, 0)
    if p.subscribe(PLAYERC_OPEN_MODE) != 0:
        raise playerc_error_str()
    p.set_cmd_vel(0.0, 0.0, 0.35, 1)
    for i in range(30):
        if c.read() is None:
            raise playerc_error_str()
        print('Robot pose: (%.3f,%.3f,%.3f)' % (p.px, p.py, p.pa))

As in libplayerc, methods return 0 on success and -1 on failure (the reason
in ``playerc_error_str()``), a proxy's fields change only when
``client.read()`` delivers its data, and ``read()`` returns the ``info.id``
of the proxy that got data (``None`` on error). The client talks Zenoh
directly: ``host`` 'localhost' is the local router that ``troupe launch``
embeds, another host is that host's router (``tcp/HOST:7447``), or a Zenoh
endpoint as such (``tcp/10.0.0.2:7447``); ``port`` is the robot. The
namespace is ``$TROUPE_NAMESPACE``'s, as for the CLI.

``raise playerc_error_str()``, as Player's scripts do, works in Python 3:
the error string is also an exception.
"""

from __future__ import annotations

import math
import os
import threading
from typing import Any, Dict, List, Optional

import troupe as _troupe
from troupe import _native

# --- errors -----------------------------------------------------------------

_error = threading.local()


class playerc_error(Exception):
    """The last error, as text that can also be raised (Player's scripts ``raise playerc_error_str()``)."""

    def __init__(self, text: str):
        super().__init__(text)
        self.text = text

    def __str__(self) -> str:
        return self.text

    def __eq__(self, other: object) -> bool:
        return self.text == (other.text if isinstance(other, playerc_error) else other)

    def __hash__(self) -> int:
        return hash(self.text)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.text, name)

    # Python looks dunder methods up on the type, not through __getattr__.
    def __contains__(self, part: str) -> bool:
        return part in self.text

    def __len__(self) -> int:
        return len(self.text)

    def __iter__(self):
        return iter(self.text)

    def __add__(self, other: str) -> str:
        return self.text + other

    def __radd__(self, other: str) -> str:
        return other + self.text

    def __format__(self, spec: str) -> str:
        return format(self.text, spec)


def _fail(text: str) -> int:
    _error.text = text
    return -1


def playerc_error_str() -> playerc_error:
    """The last error of this thread (libplayerc's ``playerc_error_str``)."""
    return playerc_error(getattr(_error, "text", ""))


def _call(fn, *args: Any) -> int:
    try:
        fn(*args)
    except (_troupe.TroupeError, TimeoutError, ValueError) as e:
        return _fail(str(e))
    return 0


# --- constants ----------------------------------------------------------------

PLAYERC_OPEN_MODE = 1
PLAYERC_CLOSE_MODE = 2
PLAYERC_ERROR_MODE = 3
PLAYER_OPEN_MODE, PLAYER_CLOSE_MODE, PLAYER_ERROR_MODE = 1, 2, 3
PLAYERC_DATAMODE_PUSH = PLAYER_DATAMODE_PUSH = 1
PLAYERC_DATAMODE_PULL = PLAYER_DATAMODE_PULL = 2
PLAYER_GRIPPER_STATE_OPEN = 1
PLAYER_GRIPPER_STATE_CLOSED = 2
PLAYER_GRIPPER_STATE_MOVING = 3
PLAYER_GRIPPER_STATE_ERROR = 4
_GRIPPER_STATES = {"Open": 1, "Closed": 2, "Moving": 3, "Error": 4}

_CODES: Dict[str, int] = dict(_native.interfaces())
_NAMES: Dict[int, str] = {code: name for name, code in _CODES.items()}
for _name, _code in _CODES.items():
    globals()[f"PLAYER_{_name.upper()}_CODE"] = _code


def playerc_lookup_name(code: int) -> Optional[str]:
    """The interface named by Player code ``code`` (``playerc_lookup_name(6)`` is 'laser')."""
    return _NAMES.get(code)


def playerc_lookup_code(name: str) -> int:
    """The Player code of interface ``name``, -1 if unknown."""
    return _CODES.get(name, -1)


# --- the client ---------------------------------------------------------------


class player_devaddr:
    """A device address: ``host``, ``robot`` (the port), ``interf`` (a code), ``index``."""

    def __init__(self, robot: int = 0, interf: int = 0, index: int = 0, host: int = 0):
        self.host, self.robot, self.interf, self.index = host, robot, interf, index

    def __repr__(self) -> str:
        return f"{self.robot}:{playerc_lookup_name(self.interf)}:{self.index}"


class playerc_device_info:
    """An entry of ``client.devinfos``: ``addr`` and ``drivername``."""

    def __init__(self, addr: player_devaddr, drivername: str):
        self.addr, self.drivername = addr, drivername


class playerc_client:
    """A connection to robot ``port`` (libplayerc's ``playerc_client_t``)."""

    def __init__(self, mclient: Any, host: str, port: int):
        self.host, self.port = host, port
        self.mode = PLAYERC_DATAMODE_PUSH
        self.connected = 0
        self.devinfos: List[playerc_device_info] = []
        self.devinfo_count = 0
        self.datatime = 0.0
        self.lasttime = 0.0
        self._client: Optional[_troupe.Client] = None
        self._robot: Optional[_troupe.Robot] = None
        self._proxies: Dict[int, "_Proxy"] = {}

    def _endpoint(self) -> Optional[str]:
        host = self.host or "localhost"
        if "/" in host:
            return host
        if host in ("localhost", "127.0.0.1", "::1"):
            return None
        return f"tcp/{host}:7447"

    def connect(self) -> int:
        """Joins the network and finds robot ``port``: 0, or -1 when no router answers."""
        try:
            self._client = _troupe.connect(self._endpoint())
        except _troupe.TroupeError as e:
            return _fail(f"connecting to {self.host}:{self.port}: {e}")
        self._robot = self._client.robot(self.port)
        self.connected = 1
        return 0

    def disconnect(self) -> int:
        """Leaves the network."""
        if self._client is not None:
            self._client.close()
        self._client, self._robot, self.connected = None, None, 0
        return 0

    def datamode(self, mode: int) -> int:
        """PLAYERC_DATAMODE_PUSH (every message, one per read: the default) or _PULL (a read brings all)."""
        if mode not in (PLAYERC_DATAMODE_PUSH, PLAYERC_DATAMODE_PULL):
            return _fail(f"unknown data mode {mode}")
        self.mode = mode
        return 0

    def set_replace_rule(self, interf: int, index: int, type: int, subtype: int, replace: int) -> int:
        """Accepted; Troupe's proxies always hold the latest data."""
        return 0

    def get_devlist(self) -> int:
        """Fills ``devinfos`` / ``devinfo_count`` with the robot's live devices."""
        if self._client is None:
            return _fail("not connected: call connect() first")
        try:
            devices = self._client.devices(self.port)
        except _troupe.TroupeError as e:
            return _fail(str(e))
        self.devinfos = [
            playerc_device_info(player_devaddr(d.robot, _CODES.get(d.interface, 0), d.index), d.driver)
            for d in devices
        ]
        self.devinfo_count = len(self.devinfos)
        return 0

    def peek(self, timeout: int) -> int:
        """1 when data waits (within ``timeout`` ms), 0 when none."""
        return 1 if any(p._feed_fresh() for p in self._proxies.values()) else 0

    def read(self, timeout: float = 10.0) -> Optional[int]:
        """Waits for data; returns the ``info.id`` of the proxy that got it, None on error.

        PUSH mode delivers one message per call, in order of arrival; PULL
        mode everything new at once (the id of the last proxy updated).
        """
        if self._client is None:
            _fail("not connected: call connect() first")
            return None
        session = self._client._session
        try:
            if self.mode == PLAYERC_DATAMODE_PUSH:
                ids = [session.next(timeout)]
            else:
                # PULL: a round brings every subscribed device's newest data.
                session.wait(timeout)
                ids = [i for i, p in self._proxies.items() if p._feed_fresh()]
        except TimeoutError:
            _fail(f"no data from {self.host}:{self.port} within {timeout} s")
            return None
        last = None
        for i in ids:
            proxy = self._proxies.get(i)
            if proxy is not None:
                proxy._update()
                self.datatime = max(self.datatime, proxy.info.datatime)
                last = proxy.info.id
        # Data of a proxy unsubscribed since it arrived: wait for the next.
        return last if last is not None else self.read(timeout)


class playerc_device:
    """A proxy's ``info``: ``addr``, ``drivername``, ``subscribed``, ``datatime``, ``fresh``, ``id``."""

    def __init__(self, client: playerc_client, interf: str, index: int, id: int):
        self.client = client
        self.addr = player_devaddr(client.port, _CODES.get(interf, 0), index)
        self.drivername = ""
        self.subscribed = 0
        self.datatime = 0.0
        self.lasttime = 0.0
        self.fresh = 0
        self.freshgeom = 0
        self.freshconfig = 0
        self.id = id


_ids = iter(range(1, 1 << 62))


class _Proxy:
    """What every playerc proxy shares: ``info``, ``subscribe``, ``unsubscribe``."""

    interface = ""

    def __init__(self, client: playerc_client, index: int):
        self.client = client
        self.index = index
        self.info = playerc_device(client, self.interface, index, next(_ids))
        self._tp: Optional[_troupe.Proxy] = None

    def subscribe(self, access: int = PLAYERC_OPEN_MODE) -> int:
        """Subscribes: 0, or -1 when the device is not live."""
        robot = self.client._robot
        if robot is None:
            return _fail("not connected: call connect() first")
        live = {(d.interface, d.index): d.driver for d in robot.devices()}
        driver = live.get((self.interface, self.index))
        if driver is None:
            return _fail(f"{self.client.port}:{self.interface}:{self.index} is not a live device "
                         f"(troupe list shows the live ones)")
        try:
            self._tp = robot.device(self.interface, self.index)
        except _troupe.TroupeError as e:
            return _fail(str(e))
        self.info.drivername = driver
        self.info.subscribed = 1
        self.client._proxies[self._tp._feed.id] = self
        return 0

    def unsubscribe(self) -> int:
        if self._tp is not None:
            self.client._proxies.pop(self._tp._feed.id, None)
            self._tp.unsubscribe()
            self._tp = None
        self.info.subscribed = 0
        return 0

    def _feed_fresh(self) -> bool:
        return self._tp is not None and self._tp.fresh

    def _update(self) -> None:
        tp = self._tp
        if tp is None:
            return
        tp._seen = tp._feed.seq
        self.info.fresh = 1
        self._refresh(tp)
        stamps = [s for (_, s, _) in tp._cache.values()]
        if stamps:
            self.info.datatime = max(stamps)

    def _refresh(self, tp: Any) -> None:
        """Copies the latest data into the proxy's fields."""

    def _planar_geom(self) -> None:
        g = self._tp.geometry()
        self.pose = [g["pose"]["x"], g["pose"]["y"], g["pose"]["yaw"]]
        self.size = [g["size"]["length"], g["size"]["width"]]

    def _request(self, fn, *args: Any) -> int:
        if self._tp is None:
            return _fail(f"{self.interface}:{self.index} is not subscribed")
        return _call(fn, *args)


def _pose3(d: Optional[Dict[str, float]]) -> List[float]:
    return [d["x"], d["y"], d["yaw"]] if d else [0.0, 0.0, 0.0]


class playerc_position2d(_Proxy):
    """A mobile base: ``px py pa``, ``vx vy va``, ``stall``, ``pose``/``size`` after ``get_geom()``."""

    interface = "position2d"

    def __init__(self, client: playerc_client, index: int):
        super().__init__(client, index)
        self.px = self.py = self.pa = 0.0
        self.vx = self.vy = self.va = 0.0
        self.stall = 0
        self.pose = [0.0, 0.0, 0.0]
        self.size = [0.0, 0.0]

    def _refresh(self, tp: _troupe.Position2d) -> None:
        d = tp.latest("position2d/data")
        if d:
            self.px, self.py, self.pa = d["pose"]["x"], d["pose"]["y"], d["pose"]["yaw"]
            self.vx, self.vy, self.va = d["vel"]["x"], d["vel"]["y"], d["vel"]["yaw"]
            self.stall = int(d["stall"])

    def set_cmd_vel(self, vx: float, vy: float, va: float, state: int) -> int:
        return self._request(lambda: self._tp.set_velocity(vx, vy, va, bool(state)))

    def set_cmd_vel_head(self, vx: float, vy: float, pa: float, state: int) -> int:
        return _fail("set_cmd_vel_head is not supported by Troupe's position2d drivers")

    def set_cmd_pose(self, gx: float, gy: float, ga: float, state: int) -> int:
        return self._request(lambda: self._tp.go_to(gx, gy, ga))

    def set_cmd_car(self, vx: float, a: float) -> int:
        return self._request(lambda: self._tp.command("car", "position2d/cmd_car",
                                                      {"velocity": float(vx), "angle": float(a)}))

    def enable(self, enable: int) -> int:
        return self._request(lambda: self._tp.enable(bool(enable)))

    def set_odom(self, ox: float, oy: float, oa: float) -> int:
        return self._request(lambda: self._tp.set_odometry(ox, oy, oa))

    def get_geom(self) -> int:
        """Fills ``pose`` (x, y, yaw on the robot) and ``size`` (length, width)."""
        return self._request(self._planar_geom)


class playerc_laser(_Proxy):
    """A laser: ``scan_count``, ``ranges``, ``scan[i] = [range, bearing]``, ``point``, ``intensity``…"""

    interface = "laser"

    def __init__(self, client: playerc_client, index: int):
        super().__init__(client, index)
        self.pose = [0.0, 0.0, 0.0]
        self.size = [0.0, 0.0]
        self.robot_pose = [0.0, 0.0, 0.0]
        self.intensity_on = 0
        self.scan_count = 0
        self.scan_start = self.scan_res = self.range_res = self.max_range = 0.0
        self.ranges: List[float] = []
        self.scan: List[List[float]] = []
        self.point: List[List[float]] = []
        self.intensity: List[int] = []
        self.scan_id = 0
        self.laser_id = 0
        self.min_left = self.min_right = 0.0

    def _refresh(self, tp: _troupe.Laser) -> None:
        s = tp.latest("laser/scan")
        if not s:
            return
        self.ranges = list(s["ranges"])
        self.scan_count = len(self.ranges)
        self.scan_start, self.scan_res, self.max_range = s["min_angle"], s["resolution"], s["max_range"]
        self.intensity = list(s["intensity"])
        self.scan_id = s["id"]
        b = [self.scan_start + i * self.scan_res for i in range(self.scan_count)]
        self.scan = [[r, a] for r, a in zip(self.ranges, b)]
        self.point = [[r * math.cos(a), r * math.sin(a)] for r, a in zip(self.ranges, b)]
        half = self.scan_count // 2
        self.min_right = min(self.ranges[:half], default=self.max_range)
        self.min_left = min(self.ranges[half:], default=self.max_range)

    def get_geom(self) -> int:
        """Fills ``pose`` (x, y, yaw on the robot) and ``size`` (length, width)."""
        return self._request(self._planar_geom)

    def get_config(self) -> int:
        def get() -> None:
            c = self._tp.config()
            self.scan_start, self.scan_res = c["min_angle"], c["resolution"]
            self.max_range, self.range_res = c["max_range"], c["range_res"]
            self.intensity_on = int(c["intensity"])
        return self._request(get)

    def get_id(self) -> int:
        def get() -> None:
            self.laser_id = self._tp.request("get_id", "laser/get_id")["serial_number"]
        return self._request(get)


class playerc_ranger(_Proxy):
    """A ranger: ``ranges_count``, ``ranges``, ``intensities``, ``element_count``, geometry and config."""

    interface = "ranger"

    def __init__(self, client: playerc_client, index: int):
        super().__init__(client, index)
        self.element_count = 0
        self.device_pose = [0.0] * 6
        self.device_size = [0.0] * 3
        self.element_poses: List[List[float]] = []
        self.element_sizes: List[List[float]] = []
        self.min_angle = self.max_angle = self.angular_res = 0.0
        self.min_range = self.max_range = self.range_res = self.frequency = 0.0
        self.ranges_count = 0
        self.ranges: List[float] = []
        self.intensities_count = 0
        self.intensities: List[float] = []

    def _refresh(self, tp: _troupe.Ranger) -> None:
        r = tp.latest("ranger/ranges")
        if r:
            self.ranges = list(r["ranges"])
            self.ranges_count = len(self.ranges)
        i = tp.latest("ranger/intensities")
        if i:
            self.intensities = list(i["intensities"])
            self.intensities_count = len(self.intensities)

    def get_geom(self) -> int:
        def get() -> None:
            g = self._tp.geometry()
            p, s = g["pose"], g["size"]
            self.device_pose = [p["x"], p["y"], p["z"], p["roll"], p["pitch"], p["yaw"]]
            self.device_size = [s["width"], s["length"], s["height"]]
            self.element_poses = [[e["x"], e["y"], e["z"], e["roll"], e["pitch"], e["yaw"]]
                                  for e in g["element_poses"]]
            self.element_sizes = [[e["width"], e["length"], e["height"]] for e in g["element_sizes"]]
            self.element_count = len(self.element_poses)
        return self._request(get)

    def get_config(self) -> int:
        def get() -> None:
            c = self._tp.config()
            for k in ("min_angle", "max_angle", "angular_res", "min_range", "max_range", "range_res", "frequency"):
                setattr(self, k, c[k])
        return self._request(get)


class playerc_sonar(_Proxy):
    """A sonar: ``scan_count``, ``scan`` (ranges), ``pose_count``, ``poses`` after ``get_geom()``."""

    interface = "sonar"

    def __init__(self, client: playerc_client, index: int):
        super().__init__(client, index)
        self.scan_count = 0
        self.scan: List[float] = []
        self.pose_count = 0
        self.poses: List[List[float]] = []

    def _refresh(self, tp: _troupe.Sonar) -> None:
        r = tp.latest("sonar/ranges")
        if r:
            self.scan = list(r["ranges"])
            self.scan_count = len(self.scan)

    def get_geom(self) -> int:
        def get() -> None:
            self.poses = [[p["x"], p["y"], p["yaw"]] for p in self._tp.geometry()["poses"]]
            self.pose_count = len(self.poses)
        return self._request(get)


class playerc_simulation(_Proxy):
    """The simulator: model poses and properties by name."""

    interface = "simulation"

    def get_pose2d(self, name: str):
        """``(result, x, y, a)``, as Player's SWIG binding returned it."""
        if self._tp is None:
            return (_fail("simulation is not subscribed"), 0.0, 0.0, 0.0)
        try:
            p = self._tp.get_pose2d(name)
        except (_troupe.TroupeError, ValueError) as e:
            return (_fail(str(e)), 0.0, 0.0, 0.0)
        return (0, p.x, p.y, p.yaw)

    def set_pose2d(self, name: str, gx: float, gy: float, ga: float) -> int:
        return self._request(lambda: self._tp.set_pose2d(name, gx, gy, ga))

    def get_property(self, name: str, prop: str):
        """``(result, value)``."""
        if self._tp is None:
            return (_fail("simulation is not subscribed"), None)
        try:
            return (0, self._tp.get_property(name, prop))
        except (_troupe.TroupeError, ValueError) as e:
            return (_fail(str(e)), None)

    def set_property(self, name: str, prop: str, value: Any) -> int:
        return self._request(lambda: self._tp.set_property(name, prop, value))


class playerc_map(_Proxy):
    """A map: ``get_map()`` fills ``width``, ``height``, ``resolution``, ``origin``
    and ``cells`` (row-major from row 0: ``cells[x + y * width]``, -1 free, 0 unknown, +1 occupied)."""

    interface = "map"

    def __init__(self, client: playerc_client, index: int):
        super().__init__(client, index)
        self.resolution = 0.0
        self.width = self.height = 0
        self.origin = [0.0, 0.0]
        self.cells: List[int] = []

    def get_map(self) -> int:
        def get() -> None:
            w, h, res, origin, cells = self._tp.robot._native.map(self.index)
            self.width, self.height, self.resolution = w, h, res
            self.origin = [origin[0], origin[1]]
            self.cells = [c - 256 if c > 127 else c for c in cells]
        return self._request(get)


class player_localize_hypoth:
    """A hypothesis: ``mean`` (x, y, a), ``cov`` (6), ``alpha`` (its weight)."""

    def __init__(self, mean: List[float], cov: List[float], alpha: float):
        self.mean, self.cov, self.alpha = mean, cov, alpha


class playerc_localize(_Proxy):
    """A localizer: ``hypoth_count``, ``hypoths``, ``pending_count``; ``set_pose``, ``get_particles``."""

    interface = "localize"

    def __init__(self, client: playerc_client, index: int):
        super().__init__(client, index)
        self.pending_count = 0
        self.pending_time = 0.0
        self.hypoth_count = 0
        self.hypoths: List[player_localize_hypoth] = []
        self.mean = [0.0, 0.0, 0.0]
        self.variance = 0.0
        self.num_particles = 0
        self.particles: List[List[float]] = []

    def _refresh(self, tp: _troupe.Localize) -> None:
        h = tp.latest("localize/hypoths")
        if h:
            self.pending_count, self.pending_time = h["pending_count"], h["pending_time"]
            self.hypoths = [player_localize_hypoth(_pose3(x["mean"]), list(x["cov"]), x["weight"])
                            for x in h["hypoths"]]
            self.hypoth_count = len(self.hypoths)

    def set_pose(self, pose: List[float], cov: List[float]) -> int:
        return self._request(lambda: self._tp.set_pose(pose[0], pose[1], pose[2], cov))

    def get_particles(self) -> int:
        def get() -> None:
            p = self._tp.particles()
            self.mean, self.variance = _pose3(p["mean"]), p["variance"]
            self.particles = [_pose3(q["pose"]) + [q["weight"]] for q in p["particles"]]
            self.num_particles = len(self.particles)
        return self._request(get)


class playerc_planner(_Proxy):
    """A planner: ``path_valid``, ``path_done``, ``px py pa``, ``gx gy ga``, ``wx wy wa``,
    ``curr_waypoint``, ``waypoint_count``, ``waypoints`` after ``get_waypoints()``."""

    interface = "planner"

    def __init__(self, client: playerc_client, index: int):
        super().__init__(client, index)
        self.path_valid = self.path_done = 0
        self.px = self.py = self.pa = 0.0
        self.gx = self.gy = self.ga = 0.0
        self.wx = self.wy = self.wa = 0.0
        self.curr_waypoint = -1
        self.waypoint_count = 0
        self.waypoints: List[List[float]] = []

    def _refresh(self, tp: _troupe.Planner) -> None:
        s = tp.latest("planner/state")
        if s:
            self.path_valid, self.path_done = int(s["valid"]), int(s["done"])
            self.px, self.py, self.pa = _pose3(s["pose"])
            self.gx, self.gy, self.ga = _pose3(s["goal"])
            self.wx, self.wy, self.wa = _pose3(s["waypoint"])
            self.curr_waypoint, self.waypoint_count = s["waypoint_idx"], s["waypoints_count"]

    def set_cmd_pose(self, gx: float, gy: float, ga: float) -> int:
        return self._request(lambda: self._tp.set_goal(gx, gy, ga))

    def get_waypoints(self) -> int:
        def get() -> None:
            self.waypoints = [list(w) for w in self._tp.waypoints()]
            self.waypoint_count = len(self.waypoints)
        return self._request(get)

    def enable(self, state: int) -> int:
        return self._request(lambda: self._tp.enable(bool(state)))


class playerc_blobfinder(_Proxy):
    """A blobfinder: ``width``, ``height``, ``blobs_count``, ``blobs`` (each with ``id color area x y left right top bottom range``)."""

    interface = "blobfinder"

    def __init__(self, client: playerc_client, index: int):
        super().__init__(client, index)
        self.width = self.height = 0
        self.blobs_count = 0
        self.blobs: List[Any] = []

    def _refresh(self, tp: _troupe.Blobfinder) -> None:
        d = tp.latest("blobfinder/data")
        if d:
            self.width, self.height = d["width"], d["height"]
            self.blobs = [_Struct(b) for b in d["blobs"]]
            self.blobs_count = len(self.blobs)


class _Struct:
    """A C struct's fields as attributes (nested dicts too)."""

    def __init__(self, fields: Dict[str, Any]):
        for k, v in fields.items():
            setattr(self, k, _Struct(v) if isinstance(v, dict) else v)

    def __repr__(self) -> str:
        return repr(self.__dict__)


class playerc_fiducial(_Proxy):
    """A fiducial finder: ``fiducials_count``, ``fiducials`` (``id``, ``pose.px``…, ``upose``)."""

    interface = "fiducial"

    def __init__(self, client: playerc_client, index: int):
        super().__init__(client, index)
        self.fiducials_count = 0
        self.fiducials: List[Any] = []
        self.fiducial_geom: Any = None

    def _refresh(self, tp: _troupe.Fiducial) -> None:
        d = tp.latest("fiducial/data")
        if d:
            self.fiducials = [_Struct(f) for f in d["fiducials"]]
            self.fiducials_count = len(self.fiducials)

    def get_geom(self) -> int:
        def get() -> None:
            self.fiducial_geom = _Struct(self._tp.geometry())
        return self._request(get)


class playerc_gripper(_Proxy):
    """A gripper: ``state`` (PLAYER_GRIPPER_STATE_*), ``beams``, ``stored``; ``open_cmd``, ``close_cmd``, ``stop_cmd``."""

    interface = "gripper"

    def __init__(self, client: playerc_client, index: int):
        super().__init__(client, index)
        self.state = 0
        self.beams = 0
        self.stored = 0
        self.pose = [0.0, 0.0, 0.0]
        self.outer_size = [0.0, 0.0, 0.0]
        self.inner_size = [0.0, 0.0, 0.0]
        self.num_beams = 0
        self.capacity = 0

    def _refresh(self, tp: _troupe.Gripper) -> None:
        d = tp.latest("gripper/data")
        if d:
            self.state = _GRIPPER_STATES.get(d["state"], PLAYER_GRIPPER_STATE_ERROR)
            self.beams, self.stored = d["beams"], d["stored"]

    def open_cmd(self) -> int:
        return self._request(lambda: self._tp.open())

    def close_cmd(self) -> int:
        return self._request(lambda: self._tp.close())

    def stop_cmd(self) -> int:
        return self._request(lambda: self._tp.stop())

    def get_geom(self) -> int:
        def get() -> None:
            g = self._tp.geometry()
            p = g["pose"]
            self.pose = [p["x"], p["y"], p["yaw"]]
            self.outer_size = [g["outer_size"]["width"], g["outer_size"]["length"], g["outer_size"]["height"]]
            self.inner_size = [g["inner_size"]["width"], g["inner_size"]["length"], g["inner_size"]["height"]]
            self.num_beams, self.capacity = g["num_beams"], g["capacity"]
        return self._request(get)


class playerc_bumper(_Proxy):
    """Bumpers: ``bumper_count``, ``bumpers`` (1 when pressed)."""

    interface = "bumper"

    def __init__(self, client: playerc_client, index: int):
        super().__init__(client, index)
        self.bumper_count = 0
        self.bumpers: List[int] = []
        self.pose_count = 0
        self.poses: List[Any] = []

    def _refresh(self, tp: _troupe.Bumper) -> None:
        d = tp.latest("bumper/data")
        if d:
            self.bumpers = [int(b) for b in d["bumpers"]]
            self.bumper_count = len(self.bumpers)

    def get_geom(self) -> int:
        def get() -> None:
            self.poses = [_Struct(b) for b in self._tp.geometry()["bumpers"]]
            self.pose_count = len(self.poses)
        return self._request(get)


class playerc_ir(_Proxy):
    """Infrared rangers: ``data.ranges_count``, ``data.ranges``, ``data.voltages``."""

    interface = "ir"

    def __init__(self, client: playerc_client, index: int):
        super().__init__(client, index)
        self.data = _Struct({"ranges_count": 0, "ranges": [], "voltages_count": 0, "voltages": []})

    def _refresh(self, tp: _troupe.Ir) -> None:
        d = tp.latest("ir/data")
        if d:
            self.data = _Struct({"ranges_count": len(d["ranges"]), "ranges": list(d["ranges"]),
                                 "voltages_count": len(d["voltages"]), "voltages": list(d["voltages"])})


__all__ = [name for name in globals() if name.startswith(("playerc", "PLAYER", "player_"))]
