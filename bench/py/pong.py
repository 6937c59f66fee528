#!/usr/bin/env python3
"""The Python pong of `nerve bench hop` (the `nerve-python` row): an
event-driven Python agent that answers every sample on `in` with one on
`out`, as the Rust pong does. Only the sequence number is written, in
place, in a loaned sample (`zeroed=False`); the sample it answers is read
in place. The layouts are the bench's Rust payloads
(`bench/src/payloads.rs`), so the Rust ping and this pong are wired.

    pong.py --robot R --name pypong-8 -- --size 8
"""

import argparse

import nerve

NAMES = {
    8: "nerve::bench::Small8",
    4096: "nerve::bench::Frame4k",
    230400: "nerve::bench::Frame230k",
    6220800: "nerve::bench::Frame1080p",
}


def layout(size: int) -> nerve.Payload:
    """`{seq: u64}` for 8 B, `{seq: u64, rest: [u8; size - 8]}` for a frame."""
    fields = [("seq", "u64")]
    if size > 8:
        fields.append(("rest", ("u8", size - 8)))
    return nerve.payload(NAMES[size], fields)


class Pong(nerve.Agent):
    kind = "pypong"

    def new(self, setup):
        p = argparse.ArgumentParser(prog="pong.py --")
        p.add_argument("--size", type=int, default=8, choices=sorted(NAMES))
        args, _ = p.parse_known_args(setup.args)
        t = layout(args.size)
        self.inp = setup.input("in", t)
        self.out = setup.output("out", t)

    def step(self, ctx):
        out = self.out
        for m in self.inp.drain():
            echo = out.loan(zeroed=False)
            echo.seq = m.seq
            out.send(echo)


if __name__ == "__main__":
    nerve.run(Pong)
