"""A ROS 2 node over Zenoh that gives Rex a plan, written against Eclipse
Zenoh's Python API (PyPI `eclipse-zenoh`) and rosbags' Kilted type store, not
against this project's code: the other side of rex-agent/tests/ros2_plans.rs.

It is the router (listening on the endpoint of the request). It finds Rex's
subscription to the plan topic by its `MS` liveliness token (laid out as
rmw_zenoh's design document says) and hashes the type the token names with
rosbags. Once Rex publishes its first estimate (the run is going), it puts on
the plan topic's data key (`<domain>/<topic>/<type>/<hash>`, CDR serialized by
rosbags, rmw_zenoh's attachment: sequence i64 LE, timestamp i64 LE, 16, GID):

1. the CDR of a plan cut after its id (sequence 1 of publisher A);
2. a whole plan on the topic's key with another type hash (publisher B);
3. a whole plan without attachment;
4. the plan of the request (sequence 2 of publisher A).

It decodes every sample Rex publishes on the ack and outcome topics with
rosbags, keeping its bytes, and waits until it has seen an ack of the plan
with status `DONE` and the plan's outcome, or Rex's tokens vanish (60 s at
most).

stdin, line 1: {"listen": endpoint, "domain": n, "register": [[name, text]],
"plan_topic": topic, "ack_topic": topic, "outcome_topic": topic,
"estimate_topic": topic, "plan": {"id": n, "points": [{"x", "y"}], "first": 0},
"odd_ids": [n, n, n]}; it prints "ready" once subscribed. It then publishes as
above. Line 2 (any, once Rex has ended): it waits until every token it saw has
vanished (10 s at most) and prints one JSON line: the plan topic's token, what
it published, the samples of the ack and outcome topics (in the order
received: bytes in hex, type, sequence number, decoded value), the seconds from
"ready" to the plan put and from there to its final ack and outcome, whether
every token vanished, and the problems.
"""

import dataclasses
import json
import struct
import sys
import threading
import time

import numpy as np
import zenoh
from rosbags.typesys import Stores, get_typestore, get_types_from_msg
from rosbags.typesys.store import Nodetype

NUMPY = {"float32": np.float32, "float64": np.float64, "int8": np.int8, "uint8": np.uint8,
         "int16": np.int16, "uint16": np.uint16, "int32": np.int32, "uint32": np.uint32,
         "int64": np.int64, "uint64": np.uint64}


def plain(v):
    """A rosbags message as plain JSON values."""
    if dataclasses.is_dataclass(v):
        return {f.name: plain(getattr(v, f.name)) for f in dataclasses.fields(v) if not f.name.startswith("__")}
    if hasattr(v, "tolist"):
        return v.tolist()
    if isinstance(v, (list, tuple)):
        return [plain(x) for x in v]
    return v


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


def ros_type(dds):
    """`rex_msgs::msg::dds_::Plan_` -> `rex_msgs/msg/Plan`."""
    package, rest = dds.split("::msg::dds_::")
    return f"{package}/msg/{rest[:-1]}"


def parse_token(key, store):
    """An entity's liveliness token: `@ros2_lv/<domain>/<zid>/<node id>/<id>/<kind>/
    <enclave>/<namespace>/<node>/<topic>/<type>/<hash>/<qos>`."""
    c = key.split("/")
    token = {"key": key, "kind": c[5]}
    if c[5] in ("MP", "MS"):
        name = ros_type(c[10])
        token.update(topic=c[9].replace("%", "/"), dds=c[10], type=name, hash=c[11],
                     rosbags_hash=store.hash_rihs01(name))
    return token


def is_done(ack):
    """Whether an ack's decoded value says every fragment was handed over: its
    status (an enum as Rex's messages carry one: the constants of its variants,
    the variant's number, a field per variant with data) is `DONE`."""
    status = ack.get("status") or {}
    return "DONE" in status and status.get("variant") == status["DONE"]


def main():
    request = json.loads(sys.stdin.readline())
    store = get_typestore(Stores.ROS2_KILTED)
    types = {}
    for name, text in request["register"]:
        types.update(get_types_from_msg(text, name))
    store.register(types)
    plan_id = request["plan"]["id"]

    config = zenoh.Config()
    config.insert_json5("mode", '"router"')
    config.insert_json5("listen/endpoints", json.dumps([request["listen"]]))
    config.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(config)

    lock = threading.Lock()
    tokens, vanished, problems = {}, set(), []
    samples = {request["ack_topic"]: [], request["outcome_topic"]: []}
    estimates = [0]
    done_at = [None]

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

    def on_data(sample):
        chunks = str(sample.key_expr).split("/")
        topic = "/" + "/".join(chunks[1:-2])
        if topic == request["estimate_topic"]:
            with lock:
                estimates[0] += 1
            return
        if topic not in samples:
            return
        payload = sample.payload.to_bytes()
        entry = {"hex": payload.hex(), "type": ros_type(chunks[-2])}
        try:
            if payload[:4] != b"\x00\x01\x00\x00":
                raise ValueError(f"CDR header {payload[:4].hex()}")
            entry["value"] = plain(store.deserialize_cdr(payload, entry["type"]))
            attachment = sample.attachment.to_bytes() if sample.attachment is not None else b""
            if len(attachment) != 33 or attachment[16] != 16:
                raise ValueError(f"attachment {attachment.hex()}")
            entry["seq"] = struct.unpack_from("<q", attachment)[0]
        except Exception as e:
            entry["problem"] = repr(e)
        with lock:
            samples[topic].append(entry)
            value = entry.get("value") or {}
            if done_at[0] is None and value.get("plan") == plan_id:
                acks = [a.get("value") or {} for a in samples[request["ack_topic"]]]
                outcomes = [o.get("value") or {} for o in samples[request["outcome_topic"]]]
                if (any(a.get("plan") == plan_id and is_done(a) for a in acks)
                        and any(o.get("plan") == plan_id for o in outcomes)):
                    done_at[0] = time.monotonic()

    liveliness = session.liveliness().declare_subscriber("@ros2_lv/**", on_token, history=True)
    data = session.declare_subscriber(f"{request['domain']}/**", on_data)
    print("ready", flush=True)
    ready_at = time.monotonic()

    # Rex's subscription, then its first estimate.
    published = {}
    token = None
    deadline = time.monotonic() + 30.0
    while token is None and time.monotonic() < deadline:
        with lock:
            token = next((t for t in tokens.values()
                          if t["kind"] == "MS" and t["topic"] == request["plan_topic"]), None)
        time.sleep(0.02)
    while token is not None and time.monotonic() < deadline:
        with lock:
            if estimates[0] > 0:
                break
        time.sleep(0.02)
    put_at = None
    if token is None:
        problems.append(f"no MS token for {request['plan_topic']}")
    elif estimates[0] == 0:
        problems.append(f"nothing on {request['estimate_topic']}")
    else:
        name = token["type"]
        base = f"{request['domain']}/{request['plan_topic'].lstrip('/')}/{token['dds']}"
        a = session.declare_publisher(f"{base}/{token['hash']}",
                                      congestion_control=zenoh.CongestionControl.BLOCK)
        b = session.declare_publisher(f"{base}/RIHS01_{'0' * 64}",
                                      congestion_control=zenoh.CongestionControl.BLOCK)
        gid_a, gid_b = bytes([0xA1]) * 16, bytes([0xB2]) * 16

        def attachment(seq, gid):
            return struct.pack("<qqB16s", seq, time.time_ns(), 16, gid)

        def cdr(value):
            return bytes(store.serialize_cdr(build(store, name, value), name))

        malformed_id, wrong_hash_id, no_attachment_id = request["odd_ids"]
        odd = dict(request["plan"])
        malformed = cdr(dict(odd, id=malformed_id))[:8]
        a.put(malformed, attachment=attachment(1, gid_a))
        b.put(cdr(dict(odd, id=wrong_hash_id)), attachment=attachment(1, gid_b))
        a.put(cdr(dict(odd, id=no_attachment_id)))
        plan = cdr(request["plan"])
        put_at = time.monotonic()
        a.put(plan, attachment=attachment(2, gid_a))
        published = {"type": name, "hash": token["hash"], "rosbags_hash": token["rosbags_hash"],
                     "malformed": malformed.hex(), "plan": plan.hex()}
        # Until the final ack and the outcome, or Rex's end.
        deadline = put_at + 60.0
        while time.monotonic() < deadline:
            with lock:
                if done_at[0] is not None or set(tokens) <= vanished:
                    break
            time.sleep(0.05)
        a.undeclare()
        b.undeclare()

    sys.stdin.readline()
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline:
        with lock:
            if tokens and set(tokens) <= vanished:
                break
        time.sleep(0.02)
    with lock:
        answer = {
            "token": token, "published": published, "samples": samples,
            "ready_to_put_s": None if put_at is None else put_at - ready_at,
            "plan_to_done_s": None if done_at[0] is None or put_at is None else done_at[0] - put_at,
            "all_vanished": bool(tokens) and set(tokens) <= vanished, "problems": problems,
        }
    print(json.dumps(answer), flush=True)
    liveliness.undeclare()
    data.undeclare()
    session.close()


if __name__ == "__main__":
    main()
