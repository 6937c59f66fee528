"""Writes a large recording in nerve's format with the `mcap` package from
PyPI: one port (`big/blob`) whose type is a byte array, described by the
nerve schema in SCHEMA_FILE, with messages of its size until the file holds
MB megabytes. Prints the number of messages. Used by tests/tests/record.rs to
make a file that replay must stream (not load)."""

import json
import sys

from mcap.writer import CompressionType, Writer


def main(path, schema_file, megabytes):
    with open(schema_file, "rb") as f:
        schema_data = f.read()
    schema = json.loads(schema_data)
    size = schema["size"]
    count = int(megabytes) * 1024 * 1024 // size
    body = bytearray(size)
    with open(path, "wb") as out:
        w = Writer(out, compression=CompressionType.NONE, chunk_size=4 * 1024 * 1024)
        w.start(profile="", library="nerve tests")
        schema_id = w.register_schema(schema["type_name"], "nerve.schema+json", schema_data)
        channel_id = w.register_channel("big/blob", "nerve.raw", schema_id,
                                        {"robot": "r", "agent": "big", "port": "blob"})
        for i in range(count):
            body[0:8] = i.to_bytes(8, "little")
            w.add_message(channel_id, log_time=1_000_000 + i, data=bytes(body),
                          publish_time=i, sequence=i)
        w.finish()
    print(count)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], sys.argv[3])
