#!/usr/bin/env python3
"""A periodic Python agent between two Rust agents: each period it takes the
newest tick on its input `tick` (nerve::Tick) and sends its number times
the parameter `gain` (bounded: in [0, 10]) on its output `value`
(nerve::Scalar), and a tick of its own on `count` (how many periods it has
run).

    nerve start python/examples/scale.py --name scale --period 50ms
    nerve connect ticker/tick scale/tick
    nerve echo scale/value
"""

import nerve


class Scale(nerve.Agent):
    kind = "scale"
    period = 0.1  # seconds; `--period` and `nerve rate` change it

    def new(self, setup):
        self.ticks = setup.input("tick", "nerve::Tick")
        self.value = setup.output("value", "nerve::Scalar")
        self.out = setup.output("count", "nerve::Tick")
        self.gain = setup.param("gain", 2.0, min=0.0, max=10.0)
        self.seen = 0

    def step(self, ctx):
        newest = self.ticks.latest()
        if newest is not None:
            self.seen = int(newest.seq)
            self.value.send(value=self.seen * self.gain.get(), stamp_ns=ctx.now_ns)
        # written in place, in shared memory
        msg = self.out.loan()
        msg.seq = ctx.cycle + 1  # numbers start at 1, as a ticker's do
        msg.stamp_ns = ctx.now_ns
        self.out.send(msg)


if __name__ == "__main__":
    nerve.run(Scale)
