#!/usr/bin/env python3
"""The Python twin of the Rust test agent ``detector``
(tests/src/bin/detector.rs): the same sequence type, declared in Python
(``acme::Detection`` elements after an ``acme::DetectionsHeader``, at most
1,000 a sample), so that the two are wired to each other both ways.

Step ``n`` sends ``LENGTHS[(n - 1) % 4]`` detections (0, 1, 400, 401: the
third grows the port's memory, the fourth is the largest seen plus one),
detection ``j`` at ``x = j``, ``y = n``, ``id = j``, written in place; and
tries 1,001, past its maximum, which is refused (nothing loaned or sent).
What its input ``dets_in`` read, checked element by element as the Rust
detector checks, and the refusals are reported on ``report``
(``test::SeqReport``), since a Python agent has no figures.

Run by python/tests/test_package.py under the harness, and by
tests/tests/python_seq.rs on a robot (shared memory).
"""

import numpy as np

import nerve

DETECTION = nerve.payload("acme::Detection", [("x", "f32"), ("y", "f32"), ("id", "u32")])
# the Rust struct's explicit padding field is #[serde(skip)], so not in its
# layout: the 4 bytes after `count` are padding here as there
HEADER = nerve.payload("acme::DetectionsHeader", [("frame", "u64"), ("count", "u32")])
REPORT = nerve.payload("test::SeqReport", [
    ("received", "u64"),
    ("largest", "u64"),
    ("bad", "u64"),
    ("refused", "u64"),
    ("zero_copy", "u64"),
])
LENGTHS = [0, 1, 400, 401]
MAX = 1000


class SeqDetector(nerve.Agent):
    kind = "seq-detector"
    period = 0.02

    def new(self, setup):
        self.dets = setup.output_seq("dets", DETECTION, HEADER, max_len=MAX)
        self.dets_in = setup.input_seq("dets_in", DETECTION, HEADER)
        self.report = setup.output("report", REPORT)
        self.n = 0
        self.received = self.largest = self.bad = self.refused = self.zero_copy = 0
        self.refusal = ""

    def step(self, ctx):
        for m in self.dets_in.drain():
            items = m.items
            self.received += 1
            self.largest = max(self.largest, len(items))
            frame = int(m.header.frame)
            right = (int(m.header.count) == len(items)
                     and np.array_equal(items["id"], np.arange(len(items)))
                     and bool(np.all(items["y"] == np.float32(frame))))
            if not right:
                self.bad += 1
            # a view of the sample's memory, not a copy
            if len(items) and not items.flags.owndata:
                self.zero_copy += 1
            del items
        self.n += 1
        n = LENGTHS[(self.n - 1) % len(LENGTHS)]
        msg = self.dets.loan(n)
        msg.header.frame = self.n
        msg.header.count = n
        msg.items["x"] = np.arange(n, dtype=np.float32)
        msg.items["y"] = self.n
        msg.items["id"] = np.arange(n, dtype=np.uint32)
        self.dets.send(msg)
        try:
            self.dets.loan(MAX + 1)
        except ValueError as e:
            self.refused += 1
            self.refusal = str(e)
        self.report.send(received=self.received, largest=self.largest, bad=self.bad, refused=self.refused,
                         zero_copy=self.zero_copy)


if __name__ == "__main__":
    nerve.run(SeqDetector)
