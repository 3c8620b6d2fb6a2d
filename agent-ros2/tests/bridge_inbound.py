"""A ROS 2 publisher over Zenoh written against Eclipse Zenoh's Python API (PyPI
`eclipse-zenoh`) and rosbags' CDR serializer, not against this project's code:
the other side of agent-ros2/tests/bridge_inbound.rs.

It is the router (listening on the endpoint of the request), finds each
subscription's `MS` liveliness token as rmw_zenoh's design document lays it out
(tokens parsed by bridge_interop.py's parse_token), and publishes on the
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
import struct
import sys
import threading
import time

import numpy as np
import zenoh
from rosbags.typesys import Stores, get_typestore, get_types_from_msg
from rosbags.typesys.store import Nodetype

from bridge_interop import parse_token, ros_type

NUMPY = {"float32": np.float32, "float64": np.float64, "int8": np.int8, "uint8": np.uint8,
         "int16": np.int16, "uint16": np.uint16, "int32": np.int32, "uint32": np.uint32,
         "int64": np.int64, "uint64": np.uint64}


def build(store, name, value):
    """The rosbags message `name` of the plain JSON `value`."""
    _, fields = store.fielddefs[name]
    args = {}
    for field, (kind, details) in fields:
        v = value[field]
        if kind == Nodetype.NAME:
            args[field] = build(store, details, v)
        elif kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
            (inner, inner_details), _ = details
            if inner == Nodetype.NAME:
                args[field] = [build(store, inner_details, x) for x in v]
            elif inner_details[0] in NUMPY:
                args[field] = np.array(v, dtype=NUMPY[inner_details[0]])
            else:
                args[field] = list(v)
        else:
            args[field] = v
    return store.types[name](**args)


def not_a_number(value):
    """`value` with every field `x` NaN, at any depth."""
    if isinstance(value, dict):
        return {k: (float("nan") if k == "x" else not_a_number(v)) for k, v in value.items()}
    return value


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
    tokens, vanished, problems = {}, set(), []

    def on_token(sample):
        key = str(sample.key_expr)
        with lock:
            if sample.kind == zenoh.SampleKind.PUT:
                try:
                    tokens[key] = parse_token(key, store)
                except Exception as e:  # a token we cannot parse is a finding
                    problems.append(f"token {key}: {e!r}")
            else:
                vanished.add(key)

    liveliness = session.liveliness().declare_subscriber("@ros2_lv/**", on_token, history=True)
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
        dds = token["key"].split("/")[10]
        base = f"{request['domain']}/{topic['topic'].lstrip('/')}/{dds}"
        publisher = session.declare_publisher(f"{base}/{token['hash']}",
                                              congestion_control=zenoh.CongestionControl.BLOCK)
        gid = bytes([k + 1]) * 16

        def put(payload, seq, on=publisher, attach=True):
            attachment = struct.pack("<qqB16s", seq, time.time_ns(), 16, gid) if attach else None
            on.put(payload, attachment=attachment)

        values = [store.serialize_cdr(build(store, name, v), name) for v in topic["values"]]
        for seq, cdr in enumerate(values, 1):
            put(bytes(cdr), seq)
        n = len(values)
        first = bytes(values[0])
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
                put(bytes(store.serialize_cdr(build(store, name, not_a_number(topic["values"][0])), name)), n + 1)
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
