#!/usr/bin/env python3
"""A Python agent that misuses its loans on purpose, to show that memory
stays safe: each period it loans a message, keeps a numpy view of it across
``send`` (refused with BufferError), drops the view and sends, then reads
and writes the sent message (refused with RuntimeError). It reports what
happened in the message it sends (``test::LoanReport``): ``kept_view_refused``
are 1 when each misuse was refused (``use_after_send_refused``: the one
after the previous send, so from the second message on), and
``values`` holds what the view wrote before the send, so a reader can see
that the bytes it got are the ones written while the loan was the agent's.

Run by python/tests/test_package.py under the harness, and by
tests/tests/python.rs on a robot (shared memory).
"""

import nerve

REPORT = nerve.payload("test::LoanReport", [
    ("seq", "u64"),
    ("values", ("f32", 4)),
    ("kept_view_refused", "u8"),
    ("use_after_send_refused", "u8"),
    ("array_view_refused", "u8"),
])


class Loaner(nerve.Agent):
    kind = "loaner"
    period = 0.05

    def new(self, setup):
        self.out = setup.output("report", REPORT)
        self.messages = []
        self.refused = 0

    def step(self, ctx):
        m = self.out.loan()
        m.seq = ctx.cycle + 1
        view = m.values  # a numpy view into the loan
        view[:] = [1.5, 2.5, 3.5, float(ctx.cycle)]
        try:
            self.out.send(m)
            self.messages.append("a loan with a live view was sent")
            return
        except BufferError as e:
            m.kept_view_refused = 1
            self.messages.append(str(e))
        del view
        whole = m.array  # the whole sample, a view too
        try:
            self.out.send(m)
            self.messages.append("a loan with a live array was sent")
            return
        except BufferError:
            m.array_view_refused = 1
        del whole
        # the previous step's use after send (checked below, after this send)
        m.use_after_send_refused = self.refused
        self.out.send(m)
        refused = 0
        try:
            m.seq = 7
            self.messages.append("a sent message was written")
        except RuntimeError as e:
            refused += 1
            self.messages.append(str(e))
        try:
            self.messages.append(f"a sent message was read: {int(m.seq)}")
        except RuntimeError:
            refused += 1
        self.refused = 1 if refused == 2 else 0
        del self.messages[:-20]  # bounded, on a robot that runs for long


if __name__ == "__main__":
    nerve.run(Loaner)
