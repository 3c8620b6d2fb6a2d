"""A ROS 2 publisher over Zenoh written against Eclipse Zenoh's Python API (PyPI
`eclipse-zenoh`) and rosbags' CDR serializer, not against this project's code:
the other side of agent-ros2/tests/bridge_inbound.rs.

It is the router (listening on the endpoint of the request), finds each
subscription's `MS` liveliness token as rmw_zenoh's design document lays it out
(tokens parsed by tests/interop/ros2_side.py's parse_token), and publishes on the
topic's data key, `<domain>/<topic>/<type>/<hash>` with the type and hash the
token announces, each value serialized by rosbags' Kilted type store (our own
messages registered from their .msg text), with rmw_zenoh's attachment
(sequence i64 LE, timestamp i64 LE, 16, GID).

stdin, line 1: {"listen": endpoint, "domain": n, "register": [[name, text]]};
it prints "ready" once subscribed to the tokens. Line 2: {"topics": [{"topic":
name, "values": [json], "odd": [case]}]}: for each topic it waits for its
`MS` token (10 s at most), publishes the values numbered 1..n from one GID,
then the odd cases in order, and prints one JSON line: the tokens seen and
what was published. Line 3: {"end": true}: it waits until every token seen has
vanished (10 s at most) and prints {"vanished": [key]}.

The odd cases, after n values (numbering on from n):
- "malformed": n+1, the CDR of the first value cut after its first field;
- "wrong_hash": n+2 on the topic's key with another type hash;
- "repeat": the first value again, numbered 1;
- "no_attachment": the first value without an attachment;
- "skip": the first value numbered n+3 (n+2 never reached the right key);
- "nan": n+1, the first value with every float64 field `x` not a number.
"""

import json
import sys
import threading
import time
from pathlib import Path

import zenoh

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests" / "interop"))
from ros2_side import attachment, cdr, on_token, open_router, type_store  # noqa: E402


def not_a_number(value):
    """`value` with every field `x` NaN, at any depth."""
    if isinstance(value, dict):
        return {k: (float("nan") if k == "x" else not_a_number(v)) for k, v in value.items()}
    return value


def main():
    request = json.loads(sys.stdin.readline())
    store = type_store(request["register"])
    session = open_router(request["listen"])

    lock = threading.Lock()
    tokens, vanished, problems = {}, set(), []
    liveliness = session.liveliness().declare_subscriber(
        "@ros2_lv/**", on_token(lock, tokens, vanished, problems, store), history=True)
    print("ready", flush=True)

    plan = json.loads(sys.stdin.readline())
    published = {}
    for k, topic in enumerate(plan["topics"]):
        deadline = time.monotonic() + 10.0
        token = None
        while token is None and time.monotonic() < deadline:
            with lock:
                token = next((t for t in tokens.values()
                              if t["kind"] == "MS" and t["topic"] == topic["topic"]), None)
            time.sleep(0.02)
        if token is None:
            problems.append(f"no MS token for {topic['topic']}")
            continue
        name = token["type"]
        base = f"{request['domain']}/{topic['topic'].lstrip('/')}/{token['dds']}"
        publisher = session.declare_publisher(f"{base}/{token['hash']}",
                                              congestion_control=zenoh.CongestionControl.BLOCK)
        gid = bytes([k + 1]) * 16

        def put(payload, seq, on=publisher, attach=True):
            on.put(payload, attachment=attachment(seq, gid) if attach else None)

        values = [cdr(store, name, v) for v in topic["values"]]
        for seq, value in enumerate(values, 1):
            put(value, seq)
        n = len(values)
        first = values[0]
        for case in topic.get("odd", []):
            if case == "malformed":
                put(first[:8], n + 1)
            elif case == "wrong_hash":
                other = session.declare_publisher(f"{base}/RIHS01_{'0' * 64}")
                put(first, n + 2, on=other)
                other.undeclare()
            elif case == "repeat":
                put(first, 1)
            elif case == "no_attachment":
                put(first, 0, attach=False)
            elif case == "skip":
                put(first, n + 3)
            elif case == "nan":
                put(cdr(store, name, not_a_number(topic["values"][0])), n + 1)
            else:
                problems.append(f"unknown case {case}")
        published[topic["topic"]] = {"type": name, "hash": token["hash"], "gid": gid.hex()}
        publisher.undeclare()

    with lock:
        seen = list(tokens.values())
    print(json.dumps({"tokens": seen, "published": published, "problems": problems}), flush=True)

    json.loads(sys.stdin.readline())
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline:
        with lock:
            if set(tokens) <= vanished:
                break
        time.sleep(0.02)
    with lock:
        print(json.dumps({"vanished": sorted(vanished)}), flush=True)
    liveliness.undeclare()
    session.close()


if __name__ == "__main__":
    main()
