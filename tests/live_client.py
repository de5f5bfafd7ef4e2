"""A Foxglove WebSocket client for the live-view tests: connects to a dextrain live view as Foxglove
does (subprotocol foxglove.sdk.v1, then subscribe to every advertised channel), collects messages
until it has `--scenes` scene messages and `--metrics` metrics messages (or a timeout), validates every
message against the JSON Schema its channel advertised (when `jsonschema` is importable), and prints
one JSON object: the advertised channels, the collected messages' contents the tests check, and
whether every message validated.

usage: live_client.py URL [--scenes N] [--metrics N] [--timeout S] [--count-only]

--count-only (benches/live_cost.sh): subscribe and count each topic's messages and bytes until the
server closes or the timeout, without decoding them (a client that costs the machine little).
"""

import argparse
import json
import struct
import sys
import time

from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

try:
    import jsonschema
except ImportError:  # the test requires it only with REQUIRE_PYTHON_WEBSOCKETS=1
    jsonschema = None


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("url")
    ap.add_argument("--scenes", type=int, default=2)
    ap.add_argument("--metrics", type=int, default=1)
    ap.add_argument("--timeout", type=float, default=120.0)
    ap.add_argument("--count-only", action="store_true")
    a = ap.parse_args()
    if a.count_only:
        a.scenes = a.metrics = float("inf")
    deadline = time.monotonic() + a.timeout
    out = {"channels": {}, "scenes": [], "tf": [], "metrics": [], "validated": jsonschema is not None and not a.count_only, "errors": [], "counts": {}, "bytes": {}}
    with connect(a.url, subprotocols=["foxglove.sdk.v1"], max_size=None, open_timeout=30) as ws:
        out["subprotocol"] = ws.subprotocol
        info = json.loads(ws.recv(timeout=30))
        out["server_op"] = info["op"]
        out["server_name"] = info.get("name")
        channels = {}
        subs = {}
        next_sub = 1
        while time.monotonic() < deadline:
            if len(out["scenes"]) >= a.scenes and len(out["metrics"]) >= a.metrics:
                break
            try:
                m = ws.recv(timeout=max(0.1, deadline - time.monotonic()))
            except (TimeoutError, ConnectionClosed):
                # (the server stops when its command ends: what came so far is the answer)
                break
            if isinstance(m, str):
                op = json.loads(m)
                if op["op"] == "advertise":
                    new = []
                    for c in op["channels"]:
                        channels[c["id"]] = c
                        out["channels"][c["topic"]] = {"encoding": c["encoding"], "schemaName": c["schemaName"], "schemaEncoding": c["schemaEncoding"]}
                        subs[next_sub] = c
                        new.append({"id": next_sub, "channelId": c["id"]})
                        next_sub += 1
                    ws.send(json.dumps({"op": "subscribe", "subscriptions": new}))
                continue
            if m[0] != 0x01:
                continue
            sub, log_time = struct.unpack_from("<IQ", m, 1)
            c = subs[sub]
            out["counts"][c["topic"]] = out["counts"].get(c["topic"], 0) + 1
            out["bytes"][c["topic"]] = out["bytes"].get(c["topic"], 0) + len(m) - 13
            if a.count_only:
                continue
            msg = json.loads(m[13:])
            if jsonschema is not None:
                try:
                    jsonschema.validate(msg, json.loads(c["schema"]))
                except jsonschema.ValidationError as e:
                    out["validated"] = False
                    out["errors"].append(f"{c['topic']}: {e.message}")
            if c["topic"] == "/scene":
                out["scenes"].append({"log_time": log_time, "entity_ids": [e["id"] for e in msg["entities"]], "frame_ids": sorted({e["frame_id"] for e in msg["entities"]}), "deletions": [d["id"] for d in msg["deletions"]]})
            elif c["topic"] == "/tf":
                out["tf"].append([[t["parent_frame_id"], t["child_frame_id"], t["translation"]] for t in msg["transforms"]])
            elif c["topic"] == "/dextrain/metrics":
                out["metrics"].append(msg)
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main()
