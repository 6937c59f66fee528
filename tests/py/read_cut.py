"""Reads an MCAP file that may have been cut short (`nerve record` killed)
with the `mcap` package from PyPI, front to back (its StreamReader), up to
the first record it cannot read, and prints as JSON each channel's message
sequences and log times, and how the reading ended. Used by
tests/tests/record.rs."""

import json
import sys

from mcap.exceptions import McapError
from mcap.records import Channel, Message
from mcap.stream_reader import StreamReader


def main(path):
    topics = {}
    channels = {}
    ended = "complete"
    with open(path, "rb") as f:
        try:
            for record in StreamReader(f).records:
                if isinstance(record, Channel):
                    channels[record.id] = record.topic
                    topics.setdefault(record.topic, {"sequences": [], "log_times": []})
                elif isinstance(record, Message):
                    t = topics[channels[record.channel_id]]
                    t["sequences"].append(record.sequence)
                    t["log_times"].append(record.log_time)
        except McapError as e:
            ended = f"{type(e).__name__}: {e}"
    json.dump({"channels": topics, "ended": ended}, sys.stdout)


if __name__ == "__main__":
    main(sys.argv[1])
