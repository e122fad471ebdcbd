"""What Foxglove's 3D and map panels would find in an MCAP file, read with the `mcap`
package (PyPI) and the protobuf schemas the file carries (`mcap-protobuf-support`),
independently of ugv-sim and of the Foxglove SDK that wrote it.

Prints JSON:
  "topics": {topic: {"schema", "schema_encoding", "message_encoding", "count"}},
  "transforms": {"parent -> child": {"count", "first": [x, y, z], "last": [x, y, z],
                 "unit_rotations": bool}},
  "frames": {topic: [frame ids its messages are in]},
  "unreachable": [frame ids of messages with no chain of transforms to "world"],
  "fixes": {"count", "lat": [min, max], "lon": [min, max], "alt": [min, max]}.
"""

import json
import math
import sys

from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

# The schemas whose messages carry a frame id, and where it is.
FRAMED = {
    "foxglove.LaserScan": lambda m: [m.frame_id],
    "foxglove.LocationFix": lambda m: [m.frame_id],
    "foxglove.PoseInFrame": lambda m: [m.frame_id],
    "foxglove.SceneUpdate": lambda m: [e.frame_id for e in m.entities],
}


def chain_to_world(frame, parents):
    """Whether `frame` reaches "world" through the child -> parent edges."""
    seen = set()
    while frame != "world":
        if frame in seen or frame not in parents:
            return False
        seen.add(frame)
        frame = next(iter(parents[frame]))
    return True


def main(path):
    topics, transforms, frames, parents = {}, {}, {}, {}
    fixes = {"count": 0, "lat": [math.inf, -math.inf], "lon": [math.inf, -math.inf],
             "alt": [math.inf, -math.inf]}
    protobuf, decoders = DecoderFactory(), {}
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            name = schema.name if schema else None
            t = topics.setdefault(channel.topic, {
                "schema": name,
                "schema_encoding": schema.encoding if schema else None,
                "message_encoding": channel.message_encoding,
                "count": 0,
            })
            t["count"] += 1
            if channel.id not in decoders:    # the JSON topics are not the panels'
                decoders[channel.id] = protobuf.decoder_for(channel.message_encoding, schema)
            decode = decoders[channel.id]
            if decode is None:
                continue
            m = decode(message.data)
            if name == "foxglove.FrameTransform":
                key = f"{m.parent_frame_id} -> {m.child_frame_id}"
                at = [m.translation.x, m.translation.y, m.translation.z]
                q = m.rotation
                unit = abs(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w - 1.0) < 1e-9
                tf = transforms.setdefault(key, {"count": 0, "first": at,
                                                 "unit_rotations": True})
                tf["count"] += 1
                tf["last"] = at
                tf["unit_rotations"] = tf["unit_rotations"] and unit
                parents.setdefault(m.child_frame_id, set()).add(m.parent_frame_id)
            if name in FRAMED:
                ids = frames.setdefault(channel.topic, set())
                ids.update(FRAMED[name](m))
            if name == "foxglove.LocationFix":
                fixes["count"] += 1
                for key, v in (("lat", m.latitude), ("lon", m.longitude), ("alt", m.altitude)):
                    fixes[key] = [min(fixes[key][0], v), max(fixes[key][1], v)]
    every = set().union(*frames.values()) if frames else set()
    print(json.dumps({
        "topics": topics,
        "transforms": transforms,
        "frames": {k: sorted(v) for k, v in frames.items()},
        # A frame with two parents is no tree: Foxglove would pick one.
        "two_parents": sorted(c for c, p in parents.items() if len(p) > 1),
        "unreachable": sorted(f for f in every if not chain_to_world(f, parents)),
        "fixes": fixes,
    }))


if __name__ == "__main__":
    main(sys.argv[1])
