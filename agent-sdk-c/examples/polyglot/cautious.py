#!/usr/bin/env python3
"""cautious.py: a Python agent that drives the robot, slower the higher
the smoothed risk ahead, and turning away while it is high: every 100 ms it
reads the newest nerve::Scalar on `risk` and sends a nerve::VelocityCommand
on `cmd` (v = vmax * (1 - risk), omega = turn * risk). With no risk heard
yet it stands still."""

import nerve


class Cautious(nerve.Agent):
    kind = "cautious"
    period = 0.1

    def new(self, setup):
        self.risk = setup.input("risk", "nerve::Scalar")
        self.cmd = setup.output("cmd", "nerve::VelocityCommand")
        self.vmax = setup.param("vmax", 0.3, min=0.0, max=0.6)
        self.turn = setup.param("turn", 0.8, min=0.0, max=2.0)
        self.last = None

    def step(self, ctx):
        r = self.risk.latest()
        if r is not None:
            self.last = min(max(float(r.value), 0.0), 1.0)
        if self.last is None:
            return
        self.cmd.send(v=self.vmax.get() * (1.0 - self.last), omega=self.turn.get() * self.last, stamp_ns=ctx.now_ns)


if __name__ == "__main__":
    nerve.run(Cautious)
