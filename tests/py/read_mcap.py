"""Reads an MCAP file that `nerve record` wrote with the `mcap` package from
PyPI (a reader nobody here wrote) and prints what it found as JSON: each
channel with its schema, message count, and its messages decoded through the
nerve schema embedded in the file (offsets and primitive types, nothing
else). Channels of `nerve export` (JSON) are read as JSON; channels in
another encoding are listed with their message sizes. Used by tests/tests/record.rs."""

import json
import struct
import sys

from mcap.reader import make_reader

FORMATS = {"u8": "<B", "u16": "<H", "u32": "<I", "u64": "<Q", "i8": "<b", "i16": "<h",
           "i32": "<i", "i64": "<q", "f32": "<f", "f64": "<d", "bool": "<?"}


def decode(schema, data, at=0):
    kind = schema["kind"]
    if "primitive" in kind:
        fmt = FORMATS[kind["primitive"]["primitive"]]
        return struct.unpack_from(fmt, data, at)[0]
    if "array" in kind:
        element = kind["array"]["element"]
        return [decode(element, data, at + i * element["size"]) for i in range(kind["array"]["len"])]
    if "string" in kind:
        (n,) = struct.unpack_from("<I", data, at)
        n = min(n, kind["string"]["capacity"])
        return data[at + 4:at + 4 + n].decode("utf-8", "replace")
    if "sequence" in kind:
        # a header, then as many elements as the message's length holds
        header, element = kind["sequence"]["header"], kind["sequence"]["element"]
        start = at + schema["size"]
        n = (len(data) - start) // element["size"]
        return {"header": decode(header, data, at),
                "items": [decode(element, data, start + i * element["size"]) for i in range(n)]}
    return {f["name"]: decode(f["schema"], data, at + f["offset"]) for f in kind["struct"]["fields"]}


def main(path):
    channels = {}
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        for schema, channel, message in reader.iter_messages():
            c = channels.setdefault(channel.topic, {
                "message_encoding": channel.message_encoding,
                "metadata": dict(channel.metadata),
                "schema_name": schema.name,
                "schema_encoding": schema.encoding,
                "messages": [],
            })
            if schema.encoding == "jsonschema":
                # `nerve export`: the message is JSON, its schema a JSON Schema
                c["json_schema"] = json.loads(schema.data)
                c["messages"].append({"sequence": message.sequence, "log_time": message.log_time,
                                      "data": json.loads(message.data)})
                continue
            if schema.encoding != "nerve.schema+json":
                # another format (a ring's foxglove.RawImage): read_images.py reads it
                c["messages"].append({"sequence": message.sequence, "size": len(message.data)})
                continue
            nerve_schema = json.loads(schema.data)
            c["messages"].append({
                "sequence": message.sequence,
                "log_time": message.log_time,
                "publish_time": message.publish_time,
                "size": len(message.data),
                "hex": message.data.hex(),
                "data": decode(nerve_schema, message.data),
            })
    out = {
        "message_count": summary.statistics.message_count if summary and summary.statistics else None,
        "channel_count": len(summary.channels) if summary else None,
        "channels": channels,
    }
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main(sys.argv[1])
