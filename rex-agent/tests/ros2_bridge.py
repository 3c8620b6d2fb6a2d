"""A ROS 2 listener over Zenoh written against Eclipse Zenoh's Python API (PyPI
`eclipse-zenoh`) and rosbags' Kilted type store, not against this project's
code: the other side of rex-agent/tests/ros2_bridge.rs.

It is the router (listening on the endpoint of the request), subscribes to
rmw_zenoh's liveliness tokens (`@ros2_lv/**`) and to every data key of domain
0, parses each publisher's token as rmw_zenoh's design document lays it out
(tests/interop/ros2_side.py: topic, type, hash, hashed again with rosbags)
and decodes each sample's CDR with rosbags (Rex's own messages registered
from their .msg text).

stdin, line 1: {"listen": endpoint, "register": [[name, text]]}; it prints
"ready" once subscribed. Line 2 (any): it waits until every token it saw has
vanished (10 s at most), then prints one JSON line: publishers (tokens of kind
MP), per topic the samples counted, the first value decoded and the problems.
"""

import json
import sys
import threading
import time
from pathlib import Path

import zenoh

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests" / "interop"))
from ros2_side import (check_cdr_header, finish, open_router, parse_token,  # noqa: E402
                       plain, ros_type, topic_of, type_store)


def main():
    request = json.loads(sys.stdin.readline())
    store = type_store(request["register"])
    session = open_router(request["listen"])

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
                    publishers.append(parse_token(key, store))
                except Exception as e:  # a token we cannot read is a finding
                    problems.append(f"token {key}: {e!r}")

    def on_data(sample):
        key = str(sample.key_expr)
        topic = topic_of(key)
        entry = None
        try:
            payload = sample.payload.to_bytes()
            check_cdr_header(payload)
            value = plain(store.deserialize_cdr(payload, ros_type(key.split("/")[-2])))
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
    finish(answer, session, liveliness, data)


if __name__ == "__main__":
    main()
