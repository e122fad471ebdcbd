"""Summarise an MCAP file with the `mcap` package (PyPI), independently of ugv-sim.

Prints JSON: {"topics": {topic: {"schema", "schema_encoding", "message_encoding",
"count", "first_ns", "last_ns", "monotonic"}}, "metadata": [names], "attachments":
[names], "complete": bool, "error": str|null}. A file cut off (no summary, a partial
last record) is read up to its last whole record: "complete" is false and "error"
says why the stream stopped.
"""

import json
import sys

from mcap.exceptions import McapError
from mcap.records import Attachment, Channel, DataEnd, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader


def main(path):
    schemas, channels, topics = {}, {}, {}
    metadata, attachments = [], []
    complete, error = False, None
    with open(path, "rb") as f:
        try:
            for record in StreamReader(f, validate_crcs=True).records:
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    channels[record.id] = record
                    schema = schemas.get(record.schema_id)
                    topics.setdefault(
                        record.topic,
                        {
                            "schema": schema.name if schema else None,
                            "schema_encoding": schema.encoding if schema else None,
                            "message_encoding": record.message_encoding,
                            "count": 0,
                            "first_ns": None,
                            "last_ns": None,
                            "monotonic": True,
                        },
                    )
                elif isinstance(record, Message):
                    t = topics[channels[record.channel_id].topic]
                    t["count"] += 1
                    if t["last_ns"] is not None and record.log_time < t["last_ns"]:
                        t["monotonic"] = False
                    if t["first_ns"] is None:
                        t["first_ns"] = record.log_time
                    t["last_ns"] = record.log_time
                elif isinstance(record, Metadata):
                    metadata.append(record.name)
                elif isinstance(record, Attachment):
                    attachments.append(record.name)
                elif isinstance(record, (DataEnd, Footer)):
                    complete = True
        except (McapError, EOFError, ValueError, KeyError) as e:
            error = f"{type(e).__name__}: {e}"
    print(
        json.dumps(
            {
                "topics": topics,
                "metadata": metadata,
                "attachments": attachments,
                "complete": complete and error is None,
                "error": error,
            }
        )
    )


if __name__ == "__main__":
    main(sys.argv[1])
