"""Reads the image channels of an MCAP file that `nerve record` wrote, with
the `mcap` package from PyPI and Google's `protobuf` package (readers nobody
here wrote): the message class is built from the FileDescriptorSet embedded
in the file, as Foxglove does, and every foxglove.RawImage is decoded.
Prints JSON: per image channel, the schema, the metadata and each frame's
fields (the pixels as their length, a count of the given RGB colour, and the
first bytes). Used by tests/tests/record.rs."""

import json
import sys

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader


def main(path, colour):
    want = bytes(int(c) for c in colour.split(","))
    pools = {}
    channels = {}
    with open(path, "rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages():
            if channel.message_encoding != "protobuf":
                continue
            if schema.id not in pools:
                fds = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
                pool = descriptor_pool.DescriptorPool()
                for fd in fds.file:
                    pool.Add(fd)
                desc = pool.FindMessageTypeByName(schema.name)
                pools[schema.id] = message_factory.GetMessageClass(desc)
            img = pools[schema.id].FromString(message.data)
            c = channels.setdefault(channel.topic, {
                "schema_name": schema.name,
                "schema_encoding": schema.encoding,
                "metadata": dict(channel.metadata),
                "frames": [],
            })
            px = img.data
            matches = sum(1 for i in range(0, len(px) - 2, 3) if px[i:i + 3] == want) if img.encoding == "rgb8" else 0
            c["frames"].append({
                "sequence": message.sequence,
                "sec": img.timestamp.seconds,
                "nanos": img.timestamp.nanos,
                "frame_id": img.frame_id,
                "width": img.width,
                "height": img.height,
                "encoding": img.encoding,
                "step": img.step,
                "len": len(px),
                "colour": matches,
            })
    json.dump({"channels": channels}, sys.stdout)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
