#!/usr/bin/env python3
"""A Foxglove WebSocket client that is not the Foxglove SDK, for sim/tests/live_view.rs.

Connects to `ugv-sim run --live` with the `websockets` package (PyPI, pinned in
scripts/install-deps.sh), records the channels the server advertises, subscribes to
one topic as soon as it is advertised and counts its messages over a wall-clock window
that starts with the first one. Prints one JSON object on stdout:

    {"subprotocol": ..., "server": {...serverInfo...},
     "channels": [{"id", "topic", "encoding", "schemaName"}, ...],
     "topic": ..., "count": N, "window_s": W, "log_span_s": S, "first_after_s": T}

`--expect-refused` offers only the given subprotocol and reports whether the server
refused the handshake: {"refused": true, "status": 400}.

Exit codes: 0 done, 3 websockets missing, 4 could not connect, 5 no message in time.
The protocol (https://github.com/foxglove/ws-protocol, docs/spec.md): JSON text
messages with an "op" (serverInfo, advertise, unadvertise; the client sends
subscribe), binary messages whose first byte is an opcode, 1 = message data followed by
a little-endian u32 subscription id, a u64 log time (ns) and the message.
"""

import argparse
import json
import struct
import sys
import time

try:
    from websockets.exceptions import InvalidStatus
    from websockets.sync.client import connect
except ImportError:
    sys.stderr.write("the websockets package is not installed\n")
    sys.exit(3)

MESSAGE_DATA = 1


def connect_retrying(url, subprotocols, timeout_s):
    """The server may not be listening yet: retry until it is, or time out."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            return connect(url, subprotocols=subprotocols, open_timeout=5, max_size=None)
        except (ConnectionRefusedError, OSError):
            if time.monotonic() > deadline:
                raise
            time.sleep(0.05)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("url", help="ws://127.0.0.1:PORT")
    ap.add_argument("--subprotocol", action="append", default=None,
                    help="offered subprotocol (repeatable; default foxglove.sdk.v1)")
    ap.add_argument("--topic", default="/laser/scan", help="the topic to count")
    ap.add_argument("--window", type=float, default=2.0, help="seconds to count over")
    ap.add_argument("--connect-timeout", type=float, default=30.0)
    ap.add_argument("--message-timeout", type=float, default=30.0,
                    help="seconds to wait for the topic's first message")
    ap.add_argument("--expect-refused", action="store_true")
    args = ap.parse_args()
    subprotocols = args.subprotocol or ["foxglove.sdk.v1"]

    if args.expect_refused:
        try:
            ws = connect_retrying(args.url, subprotocols, args.connect_timeout)
        except InvalidStatus as e:
            print(json.dumps({"refused": True, "status": e.response.status_code}))
            return 0
        ws.close()
        print(json.dumps({"refused": False, "subprotocol": ws.subprotocol}))
        return 0

    try:
        ws = connect_retrying(args.url, subprotocols, args.connect_timeout)
    except Exception as e:  # noqa: BLE001 - reported, not hidden
        sys.stderr.write(f"connecting to {args.url}: {type(e).__name__}: {e}\n")
        return 4

    connected = time.monotonic()
    server = {}
    channels = {}
    subscription = None
    first = None
    count = 0
    log_times = []
    with ws:
        while True:
            now = time.monotonic()
            if first is None and now - connected > args.message_timeout:
                sys.stderr.write(f"no message on {args.topic} within {args.message_timeout} s; "
                                 f"advertised: {sorted(c['topic'] for c in channels.values())}\n")
                return 5
            if first is not None and now - first >= args.window:
                break
            try:
                msg = ws.recv(timeout=0.1)
            except TimeoutError:
                continue
            if isinstance(msg, str):
                m = json.loads(msg)
                op = m.get("op")
                if op == "serverInfo":
                    server = m
                elif op == "advertise":
                    for c in m["channels"]:
                        channels[c["id"]] = {k: c.get(k) for k in
                                             ("id", "topic", "encoding", "schemaName")}
                        if c["topic"] == args.topic and subscription is None:
                            subscription = 1
                            ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                                {"id": subscription, "channelId": c["id"]}]}))
                elif op == "unadvertise":
                    for cid in m.get("channelIds", []):
                        channels.pop(cid, None)
                continue
            if len(msg) < 13 or msg[0] != MESSAGE_DATA:
                continue
            sub_id, log_time = struct.unpack_from("<IQ", msg, 1)
            if sub_id != subscription:
                continue
            now = time.monotonic()
            if first is None:
                first = now
            if now - first < args.window:
                count += 1
                log_times.append(log_time)

    print(json.dumps({
        "subprotocol": ws.subprotocol,
        "server": server,
        "channels": sorted(channels.values(), key=lambda c: c["id"]),
        "topic": args.topic,
        "count": count,
        "window_s": args.window,
        "log_span_s": (max(log_times) - min(log_times)) / 1e9 if log_times else 0.0,
        "first_after_s": first - connected,
    }))
    return 0


if __name__ == "__main__":
    sys.exit(main())
