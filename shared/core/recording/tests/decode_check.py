#!/usr/bin/env python3
"""Decodes a recording with Python's `mcap` + `mcap-ros2-support` and prints every message as
one JSON object per line: topic, schema, times, sequence and the decoded fields.

Used by tests/python_decode.rs to check that ROS 2 tools read our files field by field.
Requires: pip install mcap==1.6.0 mcap-ros2-support==0.6.0
Exit status 2 when the packages are missing (the test then skips).
"""

import array
import json
import sys

try:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
except ImportError as error:  # pragma: no cover
    print(f"missing Python package: {error}", file=sys.stderr)
    sys.exit(2)


def plain(value):
    """Turns a decoded ROS message into JSON-compatible data."""
    if isinstance(value, (bool, int, float, str)) or value is None:
        return value
    if isinstance(value, (bytes, bytearray)):
        return list(value)
    if isinstance(value, (list, tuple, array.array)):
        return [plain(v) for v in value]
    if hasattr(value, "__slots__"):
        return {name: plain(getattr(value, name)) for name in value.__slots__}
    if hasattr(value, "__dict__"):
        return {name: plain(v) for name, v in vars(value).items() if not name.startswith("_")}
    raise TypeError(f"cannot convert {type(value)!r}")


def main(path):
    with open(path, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            print(
                json.dumps(
                    {
                        "topic": channel.topic,
                        "schema": schema.name,
                        "log_time": message.log_time,
                        "publish_time": message.publish_time,
                        "sequence": message.sequence,
                        "message": plain(decoded),
                    }
                )
            )


if __name__ == "__main__":
    if len(sys.argv) != 2:
        print("usage: decode_check.py FILE.mcap", file=sys.stderr)
        sys.exit(1)
    main(sys.argv[1])
