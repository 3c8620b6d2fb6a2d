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

import json
import sys
import threading
import time
from pathlib import Path

import zenoh

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests" / "interop"))
from ros2_side import (anonymous, attachment, cdr, data_key, on_token, plain,  # noqa: E402
                       ros_type, serve_router, topic_of, type_store)

FORGED = b"forged by the ROS 2 side"


def is_done(ack):
    """Whether an ack's decoded value says every fragment was handed over."""
    return "done" in json.dumps(ack).lower()


def node():
    request = json.loads(sys.stdin.readline())
    store = type_store(request["register"])
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

    def on_data(sample):
        key = str(sample.key_expr)
        topic = topic_of(key)
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
        entry = {"type": ros_type(key.split("/")[-2])}
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
    liveliness = session.liveliness().declare_subscriber(
        f"@ros2_lv/{domain}/**", on_token(lock, tokens, None, problems), history=True)
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
        pose_key = (data_key(domain, request["pose_topic"], pose["dds"], pose["hash"]) if pose else
                    data_key(domain, request["pose_topic"], "geometry_msgs::msg::dds_::PoseStamped_",
                             f"RIHS01_{'0' * 64}"))
        forged = {"pose": pose_key, "link": request["link_key"]}
        for _ in range(3):
            talker.put(pose_key, FORGED, congestion_control=block)
            talker.put(request["link_key"], FORGED, congestion_control=block)
        name = token["type"]
        key = data_key(domain, request["plan_topic"], token["dds"], token["hash"])
        publisher = talker.declare_publisher(key, congestion_control=block)
        plan = cdr(store, name, request["plan"])
        put_at = time.monotonic()
        publisher.put(plan, attachment=attachment(1, bytes([0xA1]) * 16))
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
        return serve_router(sys.argv[2])
    if sys.argv[1:] == ["node"]:
        return node()
    print(f"usage: {sys.argv[0]} router CONFIG | node", file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main())
