"""A ROS 2 listener over Zenoh written against Eclipse Zenoh's Python API (PyPI
`eclipse-zenoh`) and rosbags' Kilted type store, not against this project's
code: the other side of rex-agent/tests/ros2_bridge.rs.

It is the router (listening on the endpoint of the request), subscribes to
rmw_zenoh's liveliness tokens (`@ros2_lv/**`) and to every data key of domain
0, parses each publisher's token as rmw_zenoh's design document lays it out
(topic, type, hash, hashed again with rosbags) and decodes each sample's CDR
with rosbags (Rex's own messages registered from their .msg text).

stdin, line 1: {"listen": endpoint, "register": [[name, text]]}; it prints
"ready" once subscribed. Line 2 (any): it waits until every token it saw has
vanished (10 s at most), then prints one JSON line: publishers (tokens of kind
MP), per topic the samples counted, the first value decoded and the problems.
"""

import dataclasses
import json
import sys
import threading
import time

import zenoh
from rosbags.typesys import Stores, get_typestore, get_types_from_msg


def plain(v):
    if dataclasses.is_dataclass(v):
        return {f.name: plain(getattr(v, f.name)) for f in dataclasses.fields(v) if not f.name.startswith("__")}
    if hasattr(v, "tolist"):
        return v.tolist()
    if isinstance(v, (list, tuple)):
        return [plain(x) for x in v]
    return v


def ros_type(dds):
    """`geometry_msgs::msg::dds_::PoseStamped_` -> `geometry_msgs/msg/PoseStamped`."""
    package, rest = dds.split("::msg::dds_::")
    return f"{package}/msg/{rest[:-1]}"


def main():
    request = json.loads(sys.stdin.readline())
    store = get_typestore(Stores.ROS2_KILTED)
    types = {}
    for name, text in request["register"]:
        types.update(get_types_from_msg(text, name))
    store.register(types)

    config = zenoh.Config()
    config.insert_json5("mode", '"router"')
    config.insert_json5("listen/endpoints", json.dumps([request["listen"]]))
    config.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(config)

    lock = threading.Lock()
    publishers, seen, vanished, topics, problems = [], set(), set(), {}, []

    def on_token(sample):
        key = str(sample.key_expr)
        with lock:
            if sample.kind != zenoh.SampleKind.PUT:
                vanished.add(key)
                return
            seen.add(key)
            c = key.split("/")
            if len(c) > 5 and c[5] == "MP":
                try:
                    name = ros_type(c[10])
                    publishers.append({"topic": c[9].replace("%", "/"), "type": name, "hash": c[11],
                                       "rosbags_hash": store.hash_rihs01(name)})
                except Exception as e:  # a token we cannot read is a finding
                    problems.append(f"token {key}: {e!r}")

    def on_data(sample):
        key = str(sample.key_expr)
        chunks = key.split("/")
        topic = "/" + "/".join(chunks[1:-2])
        entry = None
        try:
            payload = sample.payload.to_bytes()
            if payload[:4] != b"\x00\x01\x00\x00":
                raise ValueError(f"CDR header {payload[:4].hex()}")
            value = plain(store.deserialize_cdr(payload, ros_type(chunks[-2])))
        except Exception as e:
            entry = repr(e)
            value = None
        with lock:
            t = topics.setdefault(topic, {"samples": 0, "first": None, "problems": []})
            t["samples"] += 1
            if entry is not None:
                t["problems"].append(entry)
            elif t["first"] is None:
                t["first"] = value

    liveliness = session.liveliness().declare_subscriber("@ros2_lv/**", on_token, history=True)
    data = session.declare_subscriber("0/**", on_data)
    print("ready", flush=True)

    sys.stdin.readline()
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline:
        with lock:
            if seen and seen <= vanished:
                break
        time.sleep(0.02)
    with lock:
        answer = {"publishers": publishers, "topics": topics, "problems": problems,
                  "all_vanished": bool(seen) and seen <= vanished}
    print(json.dumps(answer), flush=True)
    liveliness.undeclare()
    data.undeclare()
    session.close()


if __name__ == "__main__":
    main()
