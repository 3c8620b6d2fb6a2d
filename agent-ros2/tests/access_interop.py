"""The ROS 2 side of a secure deployment, written against Eclipse Zenoh's
Python API (PyPI `eclipse-zenoh`), not against this project's code: the
other side of agent-ros2/tests/access_interop.rs.

`router CONFIG`: the deployment's ROS 2 router (what rmw_zenohd is), opened
with the generated configuration file as rmw_zenohd opens it
(`ZENOH_ROUTER_CONFIG_URI`); prints "ready" once it listens, then Zenoh's
log (`RUST_LOG`) until stdin closes.

`ros2 --config SESSION_CONFIG ...`: ROS 2 nodes, each a Zenoh session opened
with the generated session configuration (`ZENOH_SESSION_CONFIG_URI`, the
certificate `ros2.pem`): a listener subscribed to `--subscribe` key
expressions, and a talker. First a session with no certificate of the
authority tries to connect (`--anonymous-ca`: it trusts the router's
authority, but has no certificate of its own). Prints "ready"; on the line
"go" from stdin, the talker puts each `--put KEY=TEXT` three times, the
listener asks for the discovery tokens of `--tokens`, and after a second it
prints one JSON line: what the listener received ([key, text]), the tokens
seen, and how the anonymous session fared.
"""

import argparse
import json
import sys
import threading
import time
from pathlib import Path

import zenoh

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests" / "interop"))
from ros2_side import anonymous, serve_router  # noqa: E402


def ros2(args):
    outcome = anonymous(args.connect, args.anonymous_ca)

    received = []
    lock = threading.Lock()

    def on_sample(sample):
        with lock:
            received.append([str(sample.key_expr), sample.payload.to_string()])

    listener = zenoh.open(zenoh.Config.from_file(args.config))
    talker = zenoh.open(zenoh.Config.from_file(args.config))
    subscribers = [listener.declare_subscriber(k, on_sample) for k in args.subscribe]
    print("ready", flush=True)
    if sys.stdin.readline().strip() != "go":
        return 2
    block = zenoh.CongestionControl.BLOCK
    for _ in range(3):
        for item in args.put:
            key, text = item.split("=", 1)
            talker.put(key, text.encode(), congestion_control=block)
        time.sleep(0.1)
    tokens = []
    for reply in listener.liveliness().get(args.tokens, timeout=2.0):
        if reply.ok is not None:
            tokens.append(str(reply.ok.key_expr))
    time.sleep(1.0)
    with lock:
        seen = list(received)
    print(json.dumps({"received": seen, "tokens": tokens, "anonymous": outcome}), flush=True)
    for s in subscribers:
        s.undeclare()
    talker.close()
    listener.close()
    return 0


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="command", required=True)
    r = sub.add_parser("router")
    r.add_argument("config")
    n = sub.add_parser("ros2")
    n.add_argument("--config", required=True)
    n.add_argument("--connect", required=True)
    n.add_argument("--anonymous-ca", required=True)
    n.add_argument("--subscribe", action="append", default=[])
    n.add_argument("--put", action="append", default=[])
    n.add_argument("--tokens", required=True)
    args = ap.parse_args()
    return serve_router(args.config) if args.command == "router" else ros2(args)


if __name__ == "__main__":
    sys.exit(main())
