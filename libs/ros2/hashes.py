#!/usr/bin/env python3
"""Regenerate ROS 2 Jazzy RIHS01 type hashes (REP-2011) and cross-check two PyPI packages.

Requirements (Python 3.11):  pip install rosbags==0.11.9 ros2_pyterfaces==0.3.0

Prints a Rust `const` table of (type name, RIHS01 hash) pairs on stdout.
Exits 1 if any cross-check fails (the packages disagree, or a known reference hash is not reproduced).
Optional: `--tsv PATH` also writes `ros_type<TAB>hash<TAB>agrees|only-<pkg>` lines.

Sources:
  * rosbags:          Typestore.hash_rihs01(typename) on get_typestore(Stores.ROS2_JAZZY).
                      It has no service types at all, and it maps .msg `char` to type_id 13 (CHAR),
                      whereas rosidl maps .msg `char` to IDL uint8 (type_id 3). Only
                      service_msgs/msg/ServiceEventInfo (char[16] client_gid) is affected here, and
                      only through the service hashes.
  * ros2_pyterfaces:  ros2_pyterfaces.core.hash_rihs01(schema) on the core.<pkg>.<msg|srv> schemas
                      (DISTRO=jazzy). It has services but no tf2_msgs.
  * own:              a small REP-2011 implementation in this file over rosbags' field definitions,
                      with char->uint8 and the REP-2011 service/event composition. It must reproduce
                      rosbags for every message and rmw_zenoh design.md's example hashes.
"""

from __future__ import annotations

import argparse
import hashlib
import importlib
import json
import os
import sys
from importlib.metadata import version

os.environ["DISTRO"] = "jazzy"  # before importing ros2_pyterfaces: it picks the distro at import

from rosbags.typesys import Stores, get_typestore  # noqa: E402
from rosbags.typesys.base import Nodetype  # noqa: E402
from ros2_pyterfaces import DISTRO, Distro, core  # noqa: E402
from ros2_pyterfaces.core import Sequence, make_srv_schema  # noqa: E402

MESSAGES = [
    "std_msgs/msg/String",
    "builtin_interfaces/msg/Time",
    "sensor_msgs/msg/LaserScan",
    "sensor_msgs/msg/Range",
    "sensor_msgs/msg/Image",
    "sensor_msgs/msg/CompressedImage",
    "nav_msgs/msg/Odometry",
    "nav_msgs/msg/OccupancyGrid",
    "nav_msgs/msg/Path",
    "geometry_msgs/msg/PoseWithCovarianceStamped",
    "geometry_msgs/msg/PoseArray",
    "geometry_msgs/msg/PoseStamped",
    "geometry_msgs/msg/Twist",
    "geometry_msgs/msg/TwistStamped",
    "tf2_msgs/msg/TFMessage",
    "rosgraph_msgs/msg/Clock",
]
# service -> (request fields, response fields), in rosbags field-definition form
N = lambda t: (Nodetype.NAME, t)  # noqa: E731
SERVICES = {
    "nav_msgs/srv/GetMap": ([], [("map", N("nav_msgs/msg/OccupancyGrid"))]),
}
# Published reference values (ros2/rmw_zenoh docs/design.md examples).
REFERENCE = {
    "std_msgs/msg/String": "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
    "example_interfaces/srv/AddTwoInts": "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a",
}
_I64 = (Nodetype.BASE, ("int64", 0))
REFERENCE_SERVICES = {
    "example_interfaces/srv/AddTwoInts": ([("a", _I64), ("b", _I64)], [("sum", _I64)]),
}

# ---------------------------------------------------------------- own REP-2011 implementation
# .msg primitive -> FieldType id, after rosidl's .msg->IDL mapping (char->uint8, byte->octet).
_PRIM = {"int8": 2, "uint8": 3, "int16": 4, "uint16": 5, "int32": 6, "uint32": 7, "int64": 8,
         "uint64": 9, "float32": 10, "float64": 11, "char": 3, "bool": 15, "byte": 16, "string": 17}


def _field_type(desc) -> dict:
    kind, arg = desc
    offset, capacity = 0, 0
    if kind == Nodetype.ARRAY:
        (desc, capacity), offset = arg, 48
    elif kind == Nodetype.SEQUENCE:
        desc, bound = arg
        offset, capacity = (96, bound) if bound else (144, 0)
    kind, arg = desc
    if kind == Nodetype.NAME:
        tid, strcap, nested = 1, 0, arg
    elif arg[0] == "string" and arg[1]:
        tid, strcap, nested = 21, arg[1], ""
    else:
        tid, strcap, nested = _PRIM[arg[0]], 0, ""
    return {"type_id": offset + tid, "capacity": capacity, "string_capacity": strcap,
            "nested_type_name": nested}


def own_rihs01(root: str, defs: dict) -> str:
    seen: dict[str, dict] = {}
    todo = [root]
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        fields = [{"name": n, "type": _field_type(d)} for n, d in defs[name]] or [
            {"name": "structure_needs_at_least_one_member",
             "type": {"type_id": 3, "capacity": 0, "string_capacity": 0, "nested_type_name": ""}}]
        seen[name] = {"type_name": name, "fields": fields}
        todo += [f["type"]["nested_type_name"] for f in fields if f["type"]["nested_type_name"]]
    desc = {"type_description": seen[root],
            "referenced_type_descriptions": [seen[k] for k in sorted(seen) if k != root]}
    text = json.dumps(desc, separators=(", ", ": "), ensure_ascii=True, allow_nan=False)
    return "RIHS01_" + hashlib.sha256(text.encode("utf-8")).hexdigest()


def add_service(defs: dict, srv: str, req: list, resp: list) -> None:
    defs[f"{srv}_Request"] = req
    defs[f"{srv}_Response"] = resp
    defs[f"{srv}_Event"] = [
        ("info", N("service_msgs/msg/ServiceEventInfo")),
        ("request", (Nodetype.SEQUENCE, (N(f"{srv}_Request"), 1))),
        ("response", (Nodetype.SEQUENCE, (N(f"{srv}_Response"), 1))),
    ]
    defs[srv] = [("request_message", N(f"{srv}_Request")),
                 ("response_message", N(f"{srv}_Response")),
                 ("event_message", N(f"{srv}_Event"))]


# ---------------------------------------------------------------- package adapters
def pyterfaces_schema(typename: str):
    pkg, kind, name = typename.split("/")
    try:
        return getattr(importlib.import_module(f"ros2_pyterfaces.core.{pkg}.{kind}"), name)
    except (ImportError, AttributeError):
        return None


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tsv", help="also write ros_type<TAB>hash<TAB>status lines to this file")
    args = ap.parse_args()

    errors: list[str] = []
    if DISTRO != Distro.JAZZY:
        errors.append(f"ros2_pyterfaces picked distro {DISTRO}, not jazzy")

    store = get_typestore(Stores.ROS2_JAZZY)
    defs = {name: fields for name, (_consts, fields) in store.fielddefs.items()}
    for srv, (req, resp) in {**SERVICES, **REFERENCE_SERVICES}.items():
        add_service(defs, srv, req, resp)

    # The own implementation must reproduce the published reference hashes.
    for typename, want in REFERENCE.items():
        got = own_rihs01(typename, defs)
        if got != want:
            errors.append(f"own REP-2011 gives {got} for {typename}, reference is {want}")
    got = core.hash_rihs01(make_srv_schema(
        {"__typename": "example_interfaces/srv/AddTwoInts_Request", "a": "int64", "b": "int64"},
        {"__typename": "example_interfaces/srv/AddTwoInts_Response", "sum": "int64"}))
    if got != REFERENCE["example_interfaces/srv/AddTwoInts"]:
        want = REFERENCE["example_interfaces/srv/AddTwoInts"]
        errors.append(f"ros2_pyterfaces gives {got} for AddTwoInts, reference is {want}")

    rows: list[tuple[str, str, str]] = []
    names = list(MESSAGES)
    for srv in SERVICES:
        names += [srv, f"{srv}_Request", f"{srv}_Response"]
    for typename in names:
        own = own_rihs01(typename, defs)
        results: dict[str, str] = {}
        if typename in store.fielddefs:
            results["rosbags"] = store.hash_rihs01(typename)
            if results["rosbags"] != own:
                errors.append(f"{typename}: rosbags {results['rosbags']} != own {own}")
        schema = pyterfaces_schema(typename)
        if schema is not None:
            results["ros2_pyterfaces"] = core.hash_rihs01(schema)
        elif typename == "tf2_msgs/msg/TFMessage":
            # Not shipped by ros2_pyterfaces: compose tf2_msgs/TFMessage (one field,
            # geometry_msgs/TransformStamped[] transforms) from its geometry_msgs schema, as
            # a supplementary check; the status column still says only-rosbags.
            tfm = {"__typename": typename,
                   "transforms": Sequence(pyterfaces_schema("geometry_msgs/msg/TransformStamped"))}
            extra = core.hash_rihs01(tfm)
            if extra != own:
                errors.append(f"{typename}: ros2_pyterfaces-composed {extra} != own {own}")
        if typename not in store.fielddefs:
            # rosbags has no services: check ros2_pyterfaces against own (rosbags field defs).
            if results.get("ros2_pyterfaces") != own:
                errors.append(f"{typename}: ros2_pyterfaces {results.get('ros2_pyterfaces')} "
                              f"!= own {own}")
        if not results:
            errors.append(f"{typename}: neither package knows it")
            continue
        values = set(results.values())
        if len(values) > 1:
            errors.append(f"{typename}: packages disagree: {results}")
            continue
        status = "agrees" if len(results) == 2 else f"only-{next(iter(results))}"
        rows.append((typename, values.pop(), status))

    print("// ROS 2 Jazzy RIHS01 type hashes (REP-2011), generated by ros2_hashes.py from")
    print(f"// rosbags {version('rosbags')} and ros2_pyterfaces {version('ros2_pyterfaces')}.")
    print("pub const ROS2_TYPE_HASHES: &[(&str, &str)] = &[")
    for typename, digest, status in rows:
        note = "" if status == "agrees" else f" // {status}"
        print(f'    ("{typename}", "{digest}"),{note}')
    print("];")

    if args.tsv:
        with open(args.tsv, "w", encoding="utf-8") as fh:
            fh.writelines(f"{a}\t{b}\t{c}\n" for a, b, c in rows)

    for err in errors:
        print(f"error: {err}", file=sys.stderr)
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
