#!/usr/bin/env python3
"""An intruder on a running, unprotected deployment, written against Eclipse
Zenoh's Python API (PyPI `eclipse-zenoh`), not against this project's code.

It joins the deployment's Zenoh network as a peer (the endpoints on the command
line), finds the launch and its processes from their presence tokens
(`<system>/_rt/<launch>/process/<name>/<epoch>`), waits for the run to start
(its instant zero announced, `<system>/_rt/<launch>/origin/<ns>`), listens to a
link as an eavesdropper would, and then sends, on the keys of two links (a
queue of plans and a sample of torques), every kind of message a careless or
hostile peer can: values of a second sender (a plan numbered out of sequence, a
plan stamped 2^63 ns, forged torques, a 10 MB body), bytes of no message
(garbage, a truncated header), and a message it overheard, sent again. It can
also ask the deployment to stop, naming itself.

The message format (41-byte header, then the value's postcard encoding) is the
one `agent-core/src/link/remote.rs` documents; the bodies are written from
postcard's specification (varints, little-endian floats).

Prints one line per kind of message, `sent <kind>=<n>`, then `sent total=<n>`;
exits 2 when the deployment does not appear in time.
"""

import argparse
import json
import secrets
import struct
import sys
import threading
import time

import zenoh

WIRE_VERSION = 1
HEADER = struct.Struct("<BQQQQQ")


def frame(fingerprint, epoch, seq, iteration, stamp_ns, body):
    return HEADER.pack(WIRE_VERSION, fingerprint, epoch, seq, iteration, stamp_ns) + body


def varint(n):
    out = bytearray()
    while True:
        byte = n & 0x7F
        n >>= 7
        if n:
            out.append(byte | 0x80)
        else:
            out.append(byte)
            return bytes(out)


def plan_body(plan_id, points):
    """A `Plan { id: u32, points: Vec<Point2 { x: f64, y: f64 }>, first: u32 }`."""
    body = varint(plan_id) + varint(len(points))
    for x, y in points:
        body += struct.pack("<dd", x, y)
    return body + varint(0)


def torques_body(values):
    """A `[f64; 4]`: a fixed array, no length."""
    return struct.pack("<4d", *values)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--connect", action="append", required=True)
    ap.add_argument("--system", required=True)
    ap.add_argument("--processes", required=True, help="comma-separated")
    ap.add_argument("--plan-key", required=True)
    ap.add_argument("--plan-fingerprint", type=int, required=True)
    ap.add_argument("--torque-key", required=True)
    ap.add_argument("--torque-fingerprint", type=int, required=True)
    ap.add_argument("--count", type=int, default=20)
    ap.add_argument("--wait", type=float, default=60.0)
    ap.add_argument("--stop-as", help="only ask the deployment to stop, naming this")
    args = ap.parse_args()

    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps("peer"))
    conf.insert_json5("connect/endpoints", json.dumps(args.connect))
    conf.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(conf)

    tokens = set()
    lock = threading.Lock()

    def on_token(sample):
        with lock:
            key = str(sample.key_expr)
            if sample.kind == zenoh.SampleKind.PUT:
                tokens.add(key)
            else:
                tokens.discard(key)

    prefix = f"{args.system}/_rt/"
    _watch = session.liveliness().declare_subscriber(
        f"{prefix}**", on_token, history=True
    )
    wanted = set(args.processes.split(","))
    deadline = time.monotonic() + args.wait
    launch = None
    while time.monotonic() < deadline:
        with lock:
            seen = list(tokens)
        # <system>/_rt/<launch>/process/<name>/<epoch>, .../origin/<ns>
        parts = [k[len(prefix):].split("/") for k in seen]
        up = {p[2] for p in parts if len(p) == 4 and p[1] == "process"}
        started = [p[0] for p in parts if len(p) == 3 and p[1] == "origin"]
        if wanted <= up and started:
            launch = started[0]
            break
        time.sleep(0.05)
    if launch is None:
        print(f"intruder: the deployment did not appear in {args.wait} s", file=sys.stderr)
        return 2
    # Let the processes take their peers' announced epochs, and the run begin.
    time.sleep(1.5)

    block = zenoh.CongestionControl.BLOCK

    def put(key, payload):
        session.put(key, payload, congestion_control=block)

    if args.stop_as is not None:
        put(f"{prefix}{launch}/stop", args.stop_as.encode())
        print("sent stop=1")
        print("sent total=1")
        return 0

    # An eavesdropper: the latest torque message that went by.
    overheard = []

    def on_torques(sample):
        overheard.append(bytes(sample.payload.to_bytes()))

    spy = session.declare_subscriber(args.torque_key, on_torques)
    while not overheard and time.monotonic() < deadline:
        time.sleep(0.01)
    spy.undeclare()
    if not overheard:
        print("intruder: no torques went by", file=sys.stderr)
        return 2
    time.sleep(0.2)

    n = args.count
    sent = {}

    def second_sender(kind, key, fingerprint, bodies, stamp_ns=0):
        epoch = secrets.randbits(64) | 1
        for seq, body in enumerate(bodies, start=1):
            put(key, frame(fingerprint, epoch, seq, seq, stamp_ns, body))
        sent[kind] = len(bodies)

    plan = plan_body(77, [(5.0, 5.0), (6.0, 5.0)])
    second_sender("plan_out_of_sequence", args.plan_key, args.plan_fingerprint, [plan] * n)
    second_sender(
        "plan_far_ahead", args.plan_key, args.plan_fingerprint, [plan] * n, stamp_ns=1 << 63
    )
    second_sender(
        "forged_torques",
        args.torque_key,
        args.torque_fingerprint,
        [torques_body([1e6, -1e6, 1e6, -1e6])] * n,
    )
    second_sender(
        "huge_body", args.plan_key, args.plan_fingerprint, [bytes(10_000_000)] * 2
    )
    for key in (args.plan_key, args.torque_key):
        for _ in range(n):
            put(key, b"\xff" * 64)
    sent["garbage"] = 2 * n
    for _ in range(n):
        put(args.plan_key, b"\x01" * 10)
    sent["truncated"] = n
    for _ in range(n):
        put(args.torque_key, overheard[-1])
    sent["replayed"] = n

    for kind, count in sent.items():
        print(f"sent {kind}={count}")
    print(f"sent total={sum(sent.values())}")
    # Let Zenoh hand everything over before the session closes.
    time.sleep(1.0)
    session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
