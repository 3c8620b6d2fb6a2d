"""The ROS 2 side of Rex's secure deployment, written against Eclipse Zenoh's
Python API (PyPI `eclipse-zenoh`) and rosbags' Kilted type store, not against
this project's code: the other side of rex-agent/tests/ros2_secure.rs.

`router CONFIG`: the deployment's ROS 2 router (what rmw_zenohd is), opened
from the configuration file `rex credentials` wrote, read as it is
(`zenoh.Config.from_file`, as rmw_zenohd reads `ZENOH_ROUTER_CONFIG_URI`);
prints "ready" once it listens, then Zenoh's log (`RUST_LOG`) until stdin
closes.

`node`: a ROS 2 node, a Zenoh session opened from the session configuration
`rex credentials` wrote (the certificate `ros2.pem`, as
`ZENOH_SESSION_CONFIG_URI` gives it to rmw_zenoh). stdin, line 1:
{"session_config": file, "connect": endpoint, "ca": file, "domain": n,
"register": [[name, .msg text]], "plan_topic", "ack_topic", "outcome_topic",
"estimate_topic", "pose_topic": topics, "plan": {"id", "points", "first"},
"link_key": key}. First a client with no certificate of the authority tries
to connect (it trusts the router's authority, has no certificate of its
own). The node subscribes to the discovery tokens, to the ack, outcome,
estimate and pose topics, and prints "ready". Once Rex's subscription to the
plan topic is announced (its `MS` token) and its first estimate arrives, it
tries what the access control must refuse: a forged pose on the pose topic's
data key (Rex only publishes it) and a forged plan on the deployment's link
key; then it puts the plan of the request on the plan topic's data key (CDR
by rosbags, rmw_zenoh's attachment: sequence i64 LE, timestamp i64 LE, 16,
GID) and decodes every sample on the ack and outcome topics until an ack of
the plan says `done` and its outcome is there (60 s at most).

Line 2 (any, once Rex has ended): it prints one JSON line: the plan topic's
token, the samples of the ack and outcome topics, the number of poses and
estimates received, whether a forged pose came back, how the anonymous
client fared, the seconds from "ready" to the plan's put and from the put to
the plan's final ack, and the problems.
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

FORGED = b"forged by the ROS 2 side"


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


def parse_token(key):
    """An entity's liveliness token: `@ros2_lv/<domain>/<zid>/<node id>/<id>/<kind>/
    <enclave>/<namespace>/<node>/<topic>/<type>/<hash>/<qos>`."""
    c = key.split("/")
    token = {"key": key, "kind": c[5]}
    if c[5] in ("MP", "MS"):
        token.update(topic=c[9].replace("%", "/"), dds=c[10], type=ros_type(c[10]), hash=c[11])
    return token


def is_done(ack):
    """Whether an ack's decoded value says every fragment was handed over."""
    return "done" in json.dumps(ack).lower()


def router(config):
    zenoh.init_log_from_env_or("error")
    session = zenoh.open(zenoh.Config.from_file(config))
    print("ready", flush=True)
    sys.stdin.read()
    session.close()
    return 0


def anonymous(connect, ca):
    """A client of the router that trusts its authority but has no
    certificate: the mutual TLS handshake must fail."""
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps("client"))
    conf.insert_json5("connect/endpoints", json.dumps([connect]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("transport/link/tls/root_ca_certificate", json.dumps(ca))
    try:
        session = zenoh.open(conf)
    except zenoh.ZError as e:
        return f"refused: {e}"
    session.close()
    return "connected"


def node():
    request = json.loads(sys.stdin.readline())
    store = get_typestore(Stores.ROS2_KILTED)
    types = {}
    for name, text in request["register"]:
        types.update(get_types_from_msg(text, name))
    store.register(types)
    plan_id = request["plan"]["id"]
    outcome = anonymous(request["connect"], request["ca"])

    # Two nodes: a listener, and a talker whose puts the listener would see
    # only through the router (a session delivers its own puts to its own
    # subscribers).
    session = zenoh.open(zenoh.Config.from_file(request["session_config"]))
    talker = zenoh.open(zenoh.Config.from_file(request["session_config"]))
    lock = threading.Lock()
    tokens, problems = {}, []
    samples = {request["ack_topic"]: [], request["outcome_topic"]: []}
    counts = {request["estimate_topic"]: 0, request["pose_topic"]: 0}
    forged_back = []
    done_at = [None]

    def on_token(sample):
        key = str(sample.key_expr)
        if sample.kind != zenoh.SampleKind.PUT:
            return
        with lock:
            try:
                tokens[key] = parse_token(key)
            except Exception as e:  # a token we cannot parse is a finding
                problems.append(f"token {key}: {e!r}")

    def on_data(sample):
        chunks = str(sample.key_expr).split("/")
        topic = "/" + "/".join(chunks[1:-2])
        payload = sample.payload.to_bytes()
        if payload == FORGED:
            with lock:
                forged_back.append(str(sample.key_expr))
            return
        if topic in counts:
            with lock:
                counts[topic] += 1
            return
        if topic not in samples:
            return
        entry = {"type": ros_type(chunks[-2])}
        try:
            entry["value"] = plain(store.deserialize_cdr(payload, entry["type"]))
        except Exception as e:
            entry["problem"] = repr(e)
        with lock:
            samples[topic].append(entry)
            acks = [a.get("value") or {} for a in samples[request["ack_topic"]]]
            outcomes = [o.get("value") or {} for o in samples[request["outcome_topic"]]]
            if (done_at[0] is None
                    and any(a.get("plan") == plan_id and is_done(a) for a in acks)
                    and any(o.get("plan") == plan_id for o in outcomes)):
                done_at[0] = time.monotonic()

    domain = request["domain"]
    liveliness = session.liveliness().declare_subscriber(f"@ros2_lv/{domain}/**", on_token,
                                                         history=True)
    subscribers = [
        session.declare_subscriber(f"{domain}/{t.lstrip('/')}/*/*", on_data)
        for t in (request["ack_topic"], request["outcome_topic"], request["estimate_topic"],
                  request["pose_topic"])
    ]
    print("ready", flush=True)
    ready_at = time.monotonic()
    # Rex's end, said on stdin: nothing more to wait for.
    ended = threading.Event()
    threading.Thread(target=lambda: (sys.stdin.readline(), ended.set()), daemon=True).start()

    def token_of(kind, topic):
        with lock:
            return next((t for t in tokens.values()
                         if t["kind"] == kind and t.get("topic") == topic), None)

    # Rex's subscription, then its first estimate.
    token = None
    deadline = time.monotonic() + 60.0
    while token is None and time.monotonic() < deadline and not ended.is_set():
        token = token_of("MS", request["plan_topic"])
        time.sleep(0.02)
    while token is not None and time.monotonic() < deadline and not ended.is_set():
        with lock:
            if counts[request["estimate_topic"]] > 0:
                break
        time.sleep(0.02)
    put_at = None
    forged = {}
    if token is None:
        problems.append(f"no MS token for {request['plan_topic']}")
    elif counts[request["estimate_topic"]] == 0:
        problems.append(f"nothing on {request['estimate_topic']}")
    else:
        block = zenoh.CongestionControl.BLOCK
        # What the access control must refuse: a pose (Rex only publishes
        # it) and a value on a link of the deployment.
        pose = token_of("MP", request["pose_topic"])
        pose_key = (f"{domain}/{request['pose_topic'].lstrip('/')}/{pose['dds']}/{pose['hash']}"
                    if pose else
                    f"{domain}/{request['pose_topic'].lstrip('/')}/"
                    f"geometry_msgs::msg::dds_::PoseStamped_/RIHS01_{'0' * 64}")
        forged = {"pose": pose_key, "link": request["link_key"]}
        for _ in range(3):
            talker.put(pose_key, FORGED, congestion_control=block)
            talker.put(request["link_key"], FORGED, congestion_control=block)
        name = token["type"]
        key = f"{domain}/{request['plan_topic'].lstrip('/')}/{token['dds']}/{token['hash']}"
        publisher = talker.declare_publisher(key, congestion_control=block)
        plan = bytes(store.serialize_cdr(build(store, name, request["plan"]), name))
        put_at = time.monotonic()
        publisher.put(plan, attachment=struct.pack("<qqB16s", 1, time.time_ns(), 16,
                                                   bytes([0xA1]) * 16))
        deadline = put_at + 60.0
        while time.monotonic() < deadline and not ended.is_set():
            with lock:
                if done_at[0] is not None:
                    break
            time.sleep(0.05)
        publisher.undeclare()

    ended.wait()
    with lock:
        answer = {
            "token": token, "samples": samples, "counts": counts, "forged": forged,
            "forged_back": forged_back, "anonymous": outcome,
            "ready_to_put_s": None if put_at is None else put_at - ready_at,
            "plan_to_done_s": None if done_at[0] is None or put_at is None else done_at[0] - put_at,
            "problems": problems,
        }
    print(json.dumps(answer), flush=True)
    liveliness.undeclare()
    for s in subscribers:
        s.undeclare()
    talker.close()
    session.close()
    return 0


def main():
    if sys.argv[1:2] == ["router"] and len(sys.argv) == 3:
        return router(sys.argv[2])
    if sys.argv[1:] == ["node"]:
        return node()
    print(f"usage: {sys.argv[0]} router CONFIG | node", file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main())
