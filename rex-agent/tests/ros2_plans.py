"""A ROS 2 node over Zenoh that gives Rex a plan, written against Eclipse
Zenoh's Python API (PyPI `eclipse-zenoh`) and rosbags' Kilted type store, not
against this project's code: the other side of rex-agent/tests/ros2_plans.rs.

It is the router (listening on the endpoint of the request). It finds Rex's
subscription to the plan topic by its `MS` liveliness token (laid out as
rmw_zenoh's design document says, parsed by tests/interop/ros2_side.py) and hashes the type the token names with
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

import json
import sys
import threading
import time
from pathlib import Path

import zenoh

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests" / "interop"))
from ros2_side import (attachment, cdr, check_cdr_header, data_key, finish,  # noqa: E402
                       on_token, open_router, plain, read_attachment, ros_type, topic_of,
                       type_store)


def is_done(ack):
    """Whether an ack's decoded value says every fragment was handed over: its
    status (an enum as Rex's messages carry one: the constants of its variants,
    the variant's number, a field per variant with data) is `DONE`."""
    status = ack.get("status") or {}
    return "DONE" in status and status.get("variant") == status["DONE"]


def main():
    request = json.loads(sys.stdin.readline())
    store = type_store(request["register"])
    plan_id = request["plan"]["id"]
    session = open_router(request["listen"])

    lock = threading.Lock()
    tokens, vanished, problems = {}, set(), []
    samples = {request["ack_topic"]: [], request["outcome_topic"]: []}
    estimates = [0]
    done_at = [None]

    def on_data(sample):
        key = str(sample.key_expr)
        topic = topic_of(key)
        if topic == request["estimate_topic"]:
            with lock:
                estimates[0] += 1
            return
        if topic not in samples:
            return
        payload = sample.payload.to_bytes()
        entry = {"hex": payload.hex(), "type": ros_type(key.split("/")[-2])}
        try:
            check_cdr_header(payload)
            entry["value"] = plain(store.deserialize_cdr(payload, entry["type"]))
            entry["seq"] = read_attachment(sample)[0]
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

    liveliness = session.liveliness().declare_subscriber(
        "@ros2_lv/**", on_token(lock, tokens, vanished, problems, store), history=True)
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
        a = session.declare_publisher(
            data_key(request["domain"], request["plan_topic"], token["dds"], token["hash"]),
            congestion_control=zenoh.CongestionControl.BLOCK)
        b = session.declare_publisher(
            data_key(request["domain"], request["plan_topic"], token["dds"], f"RIHS01_{'0' * 64}"),
            congestion_control=zenoh.CongestionControl.BLOCK)
        gid_a, gid_b = bytes([0xA1]) * 16, bytes([0xB2]) * 16

        def plan_cdr(value):
            return cdr(store, name, value)

        malformed_id, wrong_hash_id, no_attachment_id = request["odd_ids"]
        odd = dict(request["plan"])
        malformed = plan_cdr(dict(odd, id=malformed_id))[:8]
        a.put(malformed, attachment=attachment(1, gid_a))
        b.put(plan_cdr(dict(odd, id=wrong_hash_id)), attachment=attachment(1, gid_b))
        a.put(plan_cdr(dict(odd, id=no_attachment_id)))
        plan = plan_cdr(request["plan"])
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
    finish(answer, session, liveliness, data)


if __name__ == "__main__":
    main()
