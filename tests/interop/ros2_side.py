"""Our stand-in for a ROS 2 node, written against Eclipse Zenoh's Python API
(PyPI `eclipse-zenoh`) and rosbags' Kilted type store, not against this
project's code: the pieces the ROS 2 interoperability tests' scripts share
(agent-ros2/tests/{access_interop,bridge_inbound,bridge_interop}.py,
rex-agent/tests/{ros2_bridge,ros2_plans,ros2_secure}.py).

What rmw_zenoh puts on the wire is written here from its design document, as
a ROS 2 node would see it:

- a data key is `<domain>/<topic>/<DDS type>/<type hash>`, the topic without
  its leading `/`, the type as `rex_msgs::msg::dds_::Plan_`;
- a sample's attachment is the publisher's sequence number (i64 LE), its
  timestamp (i64 LE, ns since the epoch), 16 and the publisher's GID (16
  bytes): 33 bytes;
- a liveliness token is `@ros2_lv/<domain>/<zid>/<node id>/<id>/<kind>/
  <enclave>/<namespace>/<node>/<topic>/<type>/<hash>/<qos>`, each name with
  `/` written `%`, the last five only for an entity (not a node, `NN`).

A script imports it by a path computed from its own location:

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests" / "interop"))
    import ros2_side
"""

import dataclasses
import json
import struct
import sys
import time

import numpy as np
import zenoh
from rosbags.typesys import Stores, get_typestore, get_types_from_msg
from rosbags.typesys.store import Nodetype

# The numpy type of each numeric ROS 2 type, for rosbags' arrays.
NUMPY = {"float32": np.float32, "float64": np.float64, "int8": np.int8, "uint8": np.uint8,
         "int16": np.int16, "uint16": np.uint16, "int32": np.int32, "uint32": np.uint32,
         "int64": np.int64, "uint64": np.uint64}

# rmw_zenoh's QoS defaults, for the fields its compact QoS leaves empty.
QOS_DEFAULTS = {"reliability": 1, "durability": 2, "history": 1, "depth": 42}

# The encapsulation header of little-endian CDR.
CDR_HEADER = b"\x00\x01\x00\x00"


def type_store(register):
    """rosbags' Kilted type store with our own messages `register`
    (`[[name, .msg text]]`) registered."""
    store = get_typestore(Stores.ROS2_KILTED)
    types = {}
    for name, text in register:
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store


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


def cdr(store, name, value):
    """The CDR of the plain JSON `value` as the message `name`, by rosbags."""
    return bytes(store.serialize_cdr(build(store, name, value), name))


def ros_type(dds):
    """`rex_msgs::msg::dds_::Plan_` -> `rex_msgs/msg/Plan`."""
    package, rest = dds.split("::msg::dds_::")
    return f"{package}/msg/{rest[:-1]}"


def demangle(chunk):
    """A name of a token, `%` back to `/`."""
    return chunk.replace("%", "/")


def parse_qos(text):
    """rmw_zenoh's compact QoS: empty fields are the defaults."""
    parts = text.split(":")
    history, depth = parts[2].split(",")
    values = {"reliability": parts[0], "durability": parts[1], "history": history, "depth": depth}
    return {k: int(v) if v else QOS_DEFAULTS[k] for k, v in values.items()}


def parse_token(key, store=None):
    """A liveliness token's fields; for an entity also its topic, DDS type,
    ROS 2 type, hash and QoS, and with a type `store` the hash rosbags
    computes of the type."""
    c = key.split("/")
    token = {
        "key": key, "domain": int(c[1]), "zid": c[2], "node_id": int(c[3]), "id": int(c[4]),
        "kind": c[5], "enclave": demangle(c[6]), "namespace": demangle(c[7]), "node": demangle(c[8]),
    }
    if token["kind"] != "NN":
        name = ros_type(c[10])
        token.update(topic=demangle(c[9]), dds=c[10], type=name, hash=c[11], qos=parse_qos(c[12]))
        if store is not None:
            token["rosbags_hash"] = store.hash_rihs01(name)
    return token


def on_token(lock, tokens, vanished, problems, store=None):
    """The callback of a liveliness subscriber: under `lock`, each token put
    parsed into `tokens` (by key, with `store` as `parse_token`'s), each
    token deleted added to `vanished` (ignored if it is None), each token it
    cannot parse a problem."""
    def callback(sample):
        key = str(sample.key_expr)
        with lock:
            if sample.kind == zenoh.SampleKind.PUT:
                try:
                    tokens[key] = parse_token(key, store)
                except Exception as e:  # a token we cannot parse is a finding
                    problems.append(f"token {key}: {e!r}")
            elif vanished is not None:
                vanished.add(key)
    return callback


def topic_of(key):
    """The topic of a data key: `0/rex/plan/<type>/<hash>` -> `/rex/plan`."""
    return "/" + "/".join(key.split("/")[1:-2])


def data_key(domain, topic, dds, hash_):
    """The data key of `topic` with the DDS type `dds` and the type hash."""
    return f"{domain}/{topic.lstrip('/')}/{dds}/{hash_}"


def attachment(seq, gid):
    """rmw_zenoh's attachment of the sample numbered `seq` of the publisher
    `gid` (16 bytes), stamped now."""
    return struct.pack("<qqB16s", seq, time.time_ns(), 16, gid)


def read_attachment(sample):
    """A sample's attachment: (sequence, timestamp, GID); ValueError when it is
    missing or not laid out as rmw_zenoh's."""
    attached = sample.attachment.to_bytes() if sample.attachment is not None else b""
    if len(attached) != 33 or attached[16] != 16:
        raise ValueError(f"attachment of {len(attached)} bytes: {attached.hex()}")
    seq, stamp, _, gid = struct.unpack("<qqB16s", attached)
    return seq, stamp, gid


def check_cdr_header(payload):
    """ValueError unless `payload` starts with little-endian CDR's header."""
    if payload[:4] != CDR_HEADER:
        raise ValueError(f"CDR header {payload[:4].hex()}")


def open_router(listen):
    """A Zenoh router listening on the endpoint `listen`, as rmw_zenohd is,
    without multicast scouting."""
    config = zenoh.Config()
    config.insert_json5("mode", '"router"')
    config.insert_json5("listen/endpoints", json.dumps([listen]))
    config.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(config)


def serve_router(config):
    """The router of a secure deployment, opened from the configuration file
    `config` as it is (as rmw_zenohd reads `ZENOH_ROUTER_CONFIG_URI`): prints
    "ready" once it listens, then Zenoh's log (`RUST_LOG`) until stdin
    closes."""
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


def finish(answer, session, *declared):
    """Print `answer` as one JSON line, then undeclare each of `declared`
    (subscribers, publishers) and close `session`."""
    print(json.dumps(answer), flush=True)
    for d in declared:
        d.undeclare()
    session.close()
