#!/usr/bin/env python3
"""The Python twin of the Rust test agent ``caller`` (tests/src/bin/caller.rs):
the two sides of a call of a ``nerve::Tick`` answered by a ``nerve::Scalar``
whose value is twice the request's ``seq``.

* ``-- --serve``: answers service ``plan``, event-driven (woken by
  requests), and service ``plans`` with a sequence (``Seq<Scalar, Tick>``,
  at most 500), as the Rust ``caller --serve --seq`` does: the request
  back as the header, then ``seq`` scalars 0, 1, ... stamped as the
  request; it reports how many it answered on ``report``;
* default: a periodic (10 ms) client ``planner`` (timeout 400 ms) that
  keeps one call in flight and checks every answer; it reports on
  ``report`` (``test::CallReport``) what became of its calls: ``answered``,
  ``wrong``, ``timed_out``, ``gone``, ``unwired``, and the calls refused
  with nothing sent (``not_wired``, ``no_server``, ``refused``), and its
  ``steps``.

Run by tests/tests/python_calls.rs on a robot (shared memory).
"""

import sys

import numpy as np

import nerve

REPORT = nerve.payload("test::CallReport", [
    ("steps", "u64"), ("sent", "u64"), ("answered", "u64"), ("wrong", "u64"), ("timed_out", "u64"),
    ("gone", "u64"), ("unwired", "u64"), ("not_wired", "u64"), ("no_server", "u64"), ("refused", "u64"),
])


class PyServer(nerve.Agent):
    kind = "py-server"
    period = None

    def new(self, setup):
        self.plan = setup.serve("plan", "nerve::Tick", "nerve::Scalar")
        self.plans = setup.serve("plans", "nerve::Tick", nerve.sequence("nerve::Scalar", "nerve::Tick"), max_len=500)
        self.report = setup.output("report", REPORT)

    def step(self, ctx):
        n = self.plan.serve(lambda req: {"value": 2.0 * int(req.seq), "stamp_ns": int(req.stamp_ns)})
        try:
            n += self.plans.serve(self.path)
        except ValueError as e:  # an answer past max_len: refused to its caller, said here
            print(f"py-server: {e}", file=sys.stderr)
        if n:
            self.report.send(answered=self.plan.answered + self.plans.answered, steps=ctx.cycle + 1)

    def path(self, req):
        """The request back as the header, then ``seq`` scalars 0, 1, ... stamped as it."""
        items = np.zeros(int(req.seq), dtype=self.plans.response.element.dtype)
        items["value"] = np.arange(len(items))
        items["stamp_ns"] = int(req.stamp_ns)
        return req, items


class PyClient(nerve.Agent):
    kind = "py-client"
    period = 0.01

    def new(self, setup):
        self.planner = setup.client("planner", "nerve::Tick", "nerve::Scalar", timeout=0.4, max_in_flight=4)
        self.report = setup.output("report", REPORT)
        self.counts = dict.fromkeys(REPORT.dtype.names, 0)
        self.asked = {}
        self.seq = 0

    def step(self, ctx):
        c = self.counts
        c["steps"] += 1
        for done in self.planner.drain():
            asked = self.asked.pop(done.id, None)
            if done.ok:
                c["answered"] += 1
                if asked is None or float(done.answer.value) != 2.0 * asked:
                    c["wrong"] += 1
            else:
                kind = {"server_gone": "gone"}.get(done.error.kind, done.error.kind)
                c[kind if kind in ("timed_out", "gone", "unwired") else "refused"] += 1
        if self.planner.in_flight == 0:
            self.seq += 1
            try:
                self.asked[self.planner.call(seq=self.seq, stamp_ns=ctx.now_ns)] = self.seq
                c["sent"] += 1
            except nerve.CallRefused as e:
                kind = e.args[1] if len(e.args) > 1 else "refused"
                c[kind if kind in ("not_wired", "no_server") else "refused"] += 1
        self.report.send(**c)


if __name__ == "__main__":
    nerve.run(PyServer if "--serve" in sys.argv else PyClient)
