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

import dataclasses
import json
import struct
import sys
import threading
import time

import zenoh
from rosbags.typesys import Stores, get_typestore, get_types_from_msg

QOS_DEFAULTS = {"reliability": 1, "durability": 2, "history": 1, "depth": 42}


def plain(v):
    if dataclasses.is_dataclass(v):
        return {f.name: plain(getattr(v, f.name)) for f in dataclasses.fields(v) if not f.name.startswith("__")}
    if hasattr(v, "tolist"):
        return v.tolist()
    if isinstance(v, (list, tuple)):
        return [plain(x) for x in v]
    return v


def demangle(chunk):
    return chunk.replace("%", "/")


def ros_type(dds):
    """`geometry_msgs::msg::dds_::PoseStamped_` -> `geometry_msgs/msg/PoseStamped`."""
    package, rest = dds.split("::msg::dds_::")
    return f"{package}/msg/{rest[:-1]}"


def parse_qos(text):
    """rmw_zenoh's compact QoS: empty fields are the defaults."""
    parts = text.split(":")
    history, depth = parts[2].split(",")
    values = {"reliability": parts[0], "durability": parts[1], "history": history, "depth": depth}
    return {k: int(v) if v else QOS_DEFAULTS[k] for k, v in values.items()}


def parse_token(key, store):
    c = key.split("/")
    token = {
        "key": key, "domain": int(c[1]), "zid": c[2], "node_id": int(c[3]), "id": int(c[4]),
        "kind": c[5], "enclave": demangle(c[6]), "namespace": demangle(c[7]), "node": demangle(c[8]),
    }
    if token["kind"] != "NN":
        name = ros_type(c[10])
        token.update(topic=demangle(c[9]), type=name, hash=c[11], qos=parse_qos(c[12]),
                     rosbags_hash=store.hash_rihs01(name))
    return token


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
    tokens, vanished, samples, problems = {}, set(), {}, []

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
        key = str(sample.key_expr)
        payload = sample.payload.to_bytes()
        attachment = sample.attachment.to_bytes() if sample.attachment is not None else b""
        entry = {"len": len(payload)}
        try:
            if len(attachment) != 33 or attachment[16] != 16:
                raise ValueError(f"attachment of {len(attachment)} bytes: {attachment.hex()}")
            seq, stamp, _, gid = struct.unpack("<qqB16s", attachment)
            entry.update(seq=seq, stamp=stamp, gid=gid.hex())
            if payload[:4] != b"\x00\x01\x00\x00":
                raise ValueError(f"CDR header {payload[:4].hex()}")
            chunks = key.split("/")
            name = ros_type(chunks[-2])
            entry["key_hash_ok"] = chunks[-1] == store.hash_rihs01(name)
            entry["value"] = plain(store.deserialize_cdr(payload, name))
        except Exception as e:
            entry["problem"] = repr(e)
        with lock:
            samples.setdefault(key, []).append(entry)

    liveliness = session.liveliness().declare_subscriber("@ros2_lv/**", on_token, history=True)
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
    print(json.dumps(answer), flush=True)
    liveliness.undeclare()
    data.undeclare()
    session.close()


if __name__ == "__main__":
    main()
