"""A ROS 2 listener over Zenoh written against Eclipse Zenoh's Python API (PyPI
`eclipse-zenoh`) and rosbags' CDR deserializer, not against this project's
code: the other side of agent-ros2/tests/bridge_interop.rs.

It is the router (listening on the endpoint of the request), subscribes to
rmw_zenoh's liveliness tokens (`@ros2_lv/**`) and to every data key of the
domain, parses each token as rmw_zenoh's design document lays it out, checks
each sample's attachment layout (sequence i64 LE, timestamp i64 LE, 16, GID)
and CDR header, decodes the CDR with rosbags' Kilted type store (our own
messages registered from their .msg text), and hashes each type with rosbags.

stdin, line 1: {"listen": endpoint, "domain": n, "register": [[name, text]]};
it prints "ready" once subscribed. Line 2: {"expect": {key: count}, "tokens": n}:
it waits until every key has its count and every token appeared and vanished
(20 s at most), then prints one JSON line: tokens, samples, problems.
"""

import json
import sys
import threading
import time
from pathlib import Path


sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests" / "interop"))
from ros2_side import (check_cdr_header, finish, on_token, open_router, plain,  # noqa: E402
                       read_attachment, ros_type, type_store)


def main():
    request = json.loads(sys.stdin.readline())
    store = type_store(request["register"])
    session = open_router(request["listen"])

    lock = threading.Lock()
    tokens, vanished, samples, problems = {}, set(), {}, []

    def on_data(sample):
        key = str(sample.key_expr)
        payload = sample.payload.to_bytes()
        entry = {"len": len(payload)}
        try:
            seq, stamp, gid = read_attachment(sample)
            entry.update(seq=seq, stamp=stamp, gid=gid.hex())
            check_cdr_header(payload)
            chunks = key.split("/")
            name = ros_type(chunks[-2])
            entry["key_hash_ok"] = chunks[-1] == store.hash_rihs01(name)
            entry["value"] = plain(store.deserialize_cdr(payload, name))
        except Exception as e:
            entry["problem"] = repr(e)
        with lock:
            samples.setdefault(key, []).append(entry)

    liveliness = session.liveliness().declare_subscriber(
        "@ros2_lv/**", on_token(lock, tokens, vanished, problems, store), history=True)
    data = session.declare_subscriber(f"{request['domain']}/**", on_data)
    print("ready", flush=True)

    end = json.loads(sys.stdin.readline())
    deadline = time.monotonic() + 20.0
    while time.monotonic() < deadline:
        with lock:
            counted = all(len(samples.get(k, [])) >= n for k, n in end["expect"].items())
            seen = len(tokens) >= end["tokens"] and set(tokens) <= vanished
        if counted and seen:
            break
        time.sleep(0.02)
    with lock:
        answer = {"tokens": list(tokens.values()), "vanished": sorted(vanished),
                  "samples": samples, "problems": problems}
    finish(answer, session, liveliness, data)


if __name__ == "__main__":
    main()
