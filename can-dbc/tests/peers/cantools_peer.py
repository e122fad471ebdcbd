#!/usr/bin/env python3
"""An independent codec for the cross-check: cantools, driven over JSON lines.

Usage: cantools_peer.py DBC
Requests on stdin, one JSON object per line:
  {"op": "encode", "message": NAME, "signals": {NAME: physical, ...}}  -> {"data": HEX}
  {"op": "decode", "id": ID, "data": HEX}                              -> {"signals": {...}}
Errors come back as {"error": TEXT}.
"""
import json
import sys

import cantools


def main() -> int:
    db = cantools.database.load_file(sys.argv[1], strict=True)
    for line in sys.stdin:
        req = json.loads(line)
        try:
            if req["op"] == "encode":
                msg = db.get_message_by_name(req["message"])
                data = msg.encode(req["signals"], scaling=True, strict=True)
                out = {"data": data.hex()}
            elif req["op"] == "decode":
                msg = db.get_message_by_frame_id(req["id"])
                values = msg.decode(bytes.fromhex(req["data"]), decode_choices=False, scaling=True)
                out = {"signals": {k: float(v) for k, v in values.items()}}
            else:
                out = {"error": f"unknown op {req['op']!r}"}
        except Exception as exc:  # reported to the Rust side, which fails the test
            out = {"error": f"{type(exc).__name__}: {exc}"}
        sys.stdout.write(json.dumps(out) + "\n")
        sys.stdout.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main())
