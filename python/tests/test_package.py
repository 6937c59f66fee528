"""Tests of the nerve Python package in the test's own process: layouts
and the harness. Run by tests/tests/python.rs (`python -m unittest` here)."""

import json
import math
import os
import sys
import time
import unittest

import numpy as np

import nerve
from nerve.testing import Harness

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "examples"))
from scale import Scale  # noqa: E402
from loaner import Loaner  # noqa: E402 (python/tests, the directory unittest runs in)
from seq_detector import DETECTION, HEADER, SeqDetector  # noqa: E402


class Layouts(unittest.TestCase):
    def test_a_layout_is_laid_out_as_repr_c(self):
        p = nerve.payload("test::Mixed", [("a", "u8"), ("b", "f64"), ("c", ("u16", 3)), ("d", "bool")])
        self.assertEqual(p.size, 24)  # a@0, b@8, c@16..22, d@22, rounded to 8
        self.assertEqual([p.dtype.fields[n][1] for n in ("a", "b", "c", "d")], [0, 8, 16, 22])
        nested = nerve.payload("test::Nested", [("head", "u8"), ("m", p)])
        self.assertEqual(nested.dtype.fields["m"][1], 8)

    def test_a_layout_from_outside_is_checked_before_it_is_used(self):
        tick = json.loads(nerve.builtin("nerve::Tick").schema_json)
        for align in (0, 3, 1 << 20):
            bad = dict(tick, align=align)
            with self.assertRaisesRegex(ValueError, f"nerve::Tick: align {align} is not a power of two"):
                nerve.Payload(json.dumps(bad))
        outside = json.loads(json.dumps(tick))
        outside["kind"]["struct"]["fields"][1]["offset"] = 2**63
        with self.assertRaisesRegex(ValueError, "stamp_ns.*past the end|stamp_ns.*beyond"):
            nerve.Payload(json.dumps(outside))
        with self.assertRaisesRegex(ValueError, "cap"):
            nerve.payload("x::Huge", [("a", ("u8", 1 << 30))])
        with self.assertRaisesRegex(ValueError, "not a payload layout"):
            nerve.Payload('{"type_name": "x"}')

    def test_unknown_types_are_refused_with_what_to_do(self):
        with self.assertRaisesRegex(ValueError, "nerve.payload"):
            nerve.builtin("nerve::Nope")
        with self.assertRaisesRegex(TypeError, "primitive"):
            nerve.payload("x::Y", [("a", 3)])


class Harnessed(unittest.TestCase):
    def test_a_periodic_agent_steps_on_the_tests_clock(self):
        h = Harness(Scale)
        self.assertAlmostEqual(h.period, 0.1)
        h.send("tick", seq=7, stamp_ns=h.now_ns)
        h.step()
        [v] = h.output("value")
        self.assertEqual(float(v.value), 14.0)
        self.assertEqual(v.meta.sender, "scale")
        [c] = h.output("count")
        self.assertEqual(int(c.seq), 1)
        # a parameter, as `nerve param set` sets it
        h.set_param("gain", 3)
        self.assertEqual(h.param("gain"), "3")
        with self.assertRaises(ValueError):
            h.set_param("gain", "much")
        h.send("tick", seq=8, stamp_ns=h.now_ns)
        h.step()
        self.assertEqual([float(m.value) for m in h.output("value")], [24.0])
        self.assertEqual([int(m.seq) for m in h.output("count")], [2])
        # the clock: 1 s is 10 periods
        t0 = h.now_ns
        self.assertEqual(h.advance(1.0), 10)
        self.assertEqual(h.now_ns - t0, 1_000_000_000)
        self.assertEqual(len(h.output("count")), 10)
        # suspended, it does not step
        h.suspend()
        h.advance(1.0)
        self.assertEqual(h.output("count"), [])
        h.resume()
        h.advance(0.2)
        self.assertEqual(len(h.output("count")), 2)
        stats = h.input_stats()
        self.assertEqual((stats[0]["input"], stats[0]["received"]), ("tick", 2))
        h.stop()

    def test_a_thousand_cycles_take_well_under_a_second(self):
        h = Harness(Scale)
        t0 = time.monotonic()
        h.run_cycles(1000)
        wall = time.monotonic() - t0
        self.assertEqual(h.cycles, 1000)
        self.assertEqual(len(h.output("count")), 1000)
        print(f"1000 cycles of a Python agent in {wall * 1e3:.1f} ms", file=sys.stderr)
        h.stop()

    def test_a_failing_step_is_raised_with_its_traceback_and_counted(self):
        class Broken(nerve.Agent):
            kind = "broken"

            def new(self, setup):
                self.inp = setup.input("in", "nerve::Tick")

            def step(self, ctx):
                for m in self.inp.drain():
                    if int(m.seq) == 2:
                        raise ValueError("two is not allowed")

        h = Harness(Broken)
        h.send("in", seq=1)
        h.step()
        h.send("in", seq=2)
        with self.assertRaisesRegex(RuntimeError, "two is not allowed"):
            h.step()
        self.assertEqual(h.errors, 1)
        with self.assertRaisesRegex(ValueError, "no input 'out'"):
            h.send("out", seq=1)
        h.stop()

    def test_a_received_message_is_read_only_and_a_copy_holds_nothing(self):
        h = Harness(Scale)
        h.send("tick", seq=3)
        h.step()
        [v] = h.output("value")
        self.assertIsInstance(v.array, np.ndarray)
        self.assertEqual(v.to_dict()["value"], 6.0)
        c = v.copy()
        self.assertEqual(c.meta, v.meta)
        h.stop()


class Loans(unittest.TestCase):
    """A loaned message's memory is never touched after it is sent, nor
    sent while a view of it lives (python/tests/loaner.py misuses them)."""

    def test_a_view_kept_across_send_is_refused_and_a_sent_message_is_gone(self):
        h = Harness(Loaner)
        h.step()
        h.step()
        reports = h.output("report")
        self.assertEqual([int(r.seq) for r in reports], [1, 2])
        for r in reports:
            self.assertEqual(int(r.kept_view_refused), 1, h.agent.messages)
            self.assertEqual(int(r.array_view_refused), 1, h.agent.messages)
        # what the view wrote while the loan was the agent's arrived
        self.assertEqual(reports[1].values.tolist(), [1.5, 2.5, 3.5, 1.0])
        # the first step's use after send is reported by the second
        self.assertEqual(int(reports[1].use_after_send_refused), 1, h.agent.messages)
        text = "\n".join(h.agent.messages)
        self.assertIn("view(s) of its memory live", text)
        self.assertIn("was sent: its memory is the readers'", text)
        self.assertNotIn("was sent\n", text)
        h.stop()

    def test_ordinary_use_keeps_working_and_native_views_count(self):
        class Plain(nerve.Agent):
            kind = "plain"

            def new(self, setup):
                self.out = setup.output("out", "nerve::Tick")

            def step(self, ctx):
                m = self.out.loan()
                m.seq = 5
                self.out.send(m)
                self.sent = m
                self.out.send(seq=6)
                # the native loan underneath: a memoryview is an export
                raw = self.out._n.loan(True)
                view = memoryview(raw)
                self.exports = raw.exports
                try:
                    self.out._n.send(raw)
                    self.refused = False
                except BufferError:
                    self.refused = True
                view.release()
                self.out._n.send(raw)
                try:
                    memoryview(raw)
                    self.after = "a view of a sent loan"
                except BufferError as e:
                    self.after = str(e)

        h = Harness(Plain)
        h.step()
        self.assertEqual([int(m.seq) for m in h.output("out")], [5, 6, 0])
        a = h.agent
        self.assertTrue(a.sent.sent)
        self.assertIn("sent", repr(a.sent))
        with self.assertRaisesRegex(RuntimeError, "was sent"):
            a.sent.seq
        with self.assertRaisesRegex(RuntimeError, "was sent"):
            a.sent.array
        self.assertEqual((a.exports, a.refused), (1, True))
        self.assertIn("sent already", a.after)
        h.stop()


class Periods(unittest.TestCase):
    def test_a_period_out_of_range_is_a_value_error_not_an_abort(self):
        for bad in (1e20, math.nan, math.inf, -math.inf, 0.0, -1.0, 1e-9, 86401.0):
            class Bad(nerve.Agent):
                kind = "bad"
                period = bad

                def step(self, ctx):
                    pass

            with self.assertRaisesRegex(ValueError, "period", msg=str(bad)):
                Harness(Bad)
            with self.assertRaisesRegex(ValueError, "period", msg=str(bad)):
                nerve.run(Bad, ["--describe"])
        h = Harness(Scale)
        for bad in (1e20, math.nan, -1.0):
            with self.assertRaises(ValueError):
                h.set_period(bad)
            with self.assertRaises(ValueError):
                h.advance(bad)
        h.set_period(0.5)
        self.assertAlmostEqual(h.period, 0.5)
        h.stop()


class Bounds(unittest.TestCase):
    def test_a_bounded_parameter_refuses_values_outside_its_range_everywhere(self):
        # Scale's gain is in [0, 10]: set in the range, refused outside it
        # (and NaN) with the range named, as `nerve param set` would be
        h = Harness(Scale)
        for good in ("0", "10", "7.5"):
            h.set_param("gain", good)
            self.assertEqual(float(h.param("gain")), float(good))
        for bad in ("10.5", "-0.1", "NaN", "inf"):
            with self.assertRaisesRegex(ValueError, r"gain is in \[0, 10\]", msg=bad):
                h.set_param("gain", bad)
        self.assertEqual(h.param("gain"), "7.5", "a refused value changed the parameter")
        h.stop()
        # at start, as `--param gain=11` is
        with self.assertRaisesRegex(RuntimeError, r"gain is in \[0, 10\]"):
            Harness(Scale, params={"gain": "11"})

    def test_int_one_sided_and_wrong_bounds(self):
        class Counted(nerve.Agent):
            kind = "counted"
            period = 0.1

            def new(self, setup):
                self.n = setup.param("n", 3, min=1)
                self.top = setup.param("top", 5, max=8)

            def step(self, ctx):
                pass

        h = Harness(Counted)
        h.set_param("n", "1000")
        with self.assertRaisesRegex(ValueError, "n must be >= 1"):
            h.set_param("n", "0")
        with self.assertRaisesRegex(ValueError, "top must be <= 8"):
            h.set_param("top", "9")
        with self.assertRaisesRegex(ValueError, "not a valid i64"):
            h.set_param("n", "2.5")
        h.stop()

        def declaring(**bounds):
            class Bad(nerve.Agent):
                kind = "bad"
                period = 0.1

                def new(self, setup):
                    setup.param(bounds.pop("key"), bounds.pop("default"), **bounds)

                def step(self, ctx):
                    pass

            return Bad

        cases = [
            (dict(key="g", default=20.0, min=0.0, max=10.0), "default is out of its own bounds"),
            (dict(key="g", default=1.0, min=5.0, max=2.0), "min 5 is above max 2"),
            (dict(key="n", default=1, min=0.5), "min must be an int"),
            (dict(key="b", default=True, max=1), "only float and int parameters"),
            (dict(key="s", default="a", min=0), "only float and int parameters"),
            (dict(key="g", default=1.0, max="x"), "max must be a number"),
        ]
        for decl, message in cases:
            with self.assertRaisesRegex(Exception, message, msg=str(decl)):
                Harness(declaring(**decl))


class Sequences(unittest.TestCase):
    """Sequence ports (issue 42) under the harness; tests/tests/python_seq.rs
    runs the same agent against a Rust one in shared memory."""

    def test_a_sequence_type_is_the_rust_layout(self):
        s = nerve.sequence(DETECTION, HEADER)
        self.assertEqual(s.type_name, "nerve::Seq<acme::Detection, acme::DetectionsHeader>")
        self.assertEqual((s.items_at, s.element_size, s.align), (16, 12, 8))
        text = nerve.sequence("u8")
        self.assertEqual((text.type_name, text.items_at, text.header), ("nerve::Seq<u8, nerve::NoHeader>", 0, None))
        self.assertNotEqual(s.fingerprint, nerve.sequence(DETECTION).fingerprint, "the header is in the fingerprint")
        with self.assertRaisesRegex(ValueError, "fixed-size types, not sequences"):
            nerve.sequence(s)
        with self.assertRaisesRegex(ValueError, "not a .* whole 12-byte elements"):
            s.length_of(16 + 13)

    def test_a_payload_ending_in_a_sequence_is_the_sequence_after_a_header_of_the_other_fields(self):
        dets = nerve.payload("acme::DetectionsHeader", [("frame", "u64"), ("count", "u32"), ("items", [DETECTION])])
        s = nerve.sequence(DETECTION, HEADER)
        self.assertEqual((dets.type_name, dets.fingerprint), (s.type_name, s.fingerprint))
        self.assertEqual(nerve.payload("x::Text", [("items", ["u8"])]).type_name, "nerve::Seq<u8, nerve::NoHeader>")
        with self.assertRaisesRegex(TypeError, "only the last field"):
            nerve.payload("x::Bad", [("items", ["u8"]), ("n", "u32")])
        with self.assertRaisesRegex(TypeError, "written"):
            nerve.payload("x::Bad", [("n", "u32"), ("rows", ["u8"])])

    def test_lengths_zero_one_and_growth_are_sent_at_their_length_and_read_back(self):
        h = Harness(SeqDetector)
        h.run_cycles(5)
        sent = h.output("dets")
        self.assertEqual([len(m) for m in sent], [0, 1, 400, 401, 0])
        self.assertEqual([int(m.header.frame) for m in sent], [1, 2, 3, 4, 5])
        self.assertEqual(sent[3].items["id"].tolist(), list(range(401)))
        self.assertTrue(np.all(sent[3].items["y"] == 4.0))
        self.assertEqual(sent[1].to_dict(), {"header": {"frame": 2, "count": 1}, "items": [{"x": 0.0, "y": 2.0, "id": 0}]})
        for m in sent:
            h.send("dets_in", m, sender="rust")
        # fields, a list of tuples, and one that is not what its header says
        h.send("dets_in", header={"frame": 9, "count": 2}, items=[(0.0, 9.0, 0), (1.0, 9.0, 1)])
        h.send("dets_in", header={"frame": 9, "count": 3}, items=[(0.0, 9.0, 0)])
        h.step()
        report = h.output("report")[-1]
        self.assertEqual((int(report.received), int(report.largest), int(report.bad)), (7, 401, 1))
        # past its maximum: refused every step, nothing sent
        self.assertEqual(int(report.refused), 6)

    def test_a_loan_is_refused_past_its_maximum_and_spent_by_send(self):
        class Text(nerve.Agent):
            period = 0.1

            def new(self, setup):
                self.out = setup.output_seq("line", "u8", max_len=8)
                self.outcomes = []

            def step(self, ctx):
                try:
                    self.out.loan(9)
                except ValueError as e:
                    self.outcomes.append(str(e))
                m = self.out.loan(5)
                m.items[:] = np.frombuffer(b"hello", dtype=np.uint8)
                kept = m.items
                try:
                    self.out.send(m)
                except BufferError:
                    self.outcomes.append("a live view kept it")
                del kept
                self.out.send(m)
                try:
                    m.items
                except RuntimeError:
                    self.outcomes.append("spent")
                self.out.send(items=b"")
                self.out.send(items=b"12345678")

        h = Harness(Text)
        h.step()
        refusal, kept, spent = h.agent.outcomes
        self.assertIn("a sample of 9 elements is longer than the 8 the port declared", refusal)
        self.assertEqual((kept, spent), ("a live view kept it", "spent"))
        self.assertEqual([m.items.tobytes() for m in h.output("line")], [b"hello", b"", b"12345678"])
        with self.assertRaisesRegex(Exception, "give max_len"):
            Harness(type("NoMax", (nerve.Agent,), {"period": 0.1, "new": lambda self, s: s.output("x", nerve.sequence("u8")),
                                                   "step": lambda self, c: None}))


class Calls(unittest.TestCase):
    """Calls (issue 42) under the harness: a wrong declaration is refused
    at start; python/tests/harness_calls.py (run by
    tests/tests/python_calls.rs) calls and answers them."""

    def test_call_ports_in_the_harness_are_wired_to_the_test_and_checked(self):
        for declare, kind, port in ((lambda s: s.serve("plan", "nerve::Tick", "nerve::Scalar"), "service", "plan"),
                                    (lambda s: s.client("planner", "nerve::Tick", "nerve::Scalar"), "client", "planner")):
            agent = type("Calling", (nerve.Agent,), {"period": 0.1, "new": lambda self, s, d=declare: d(s),
                                                     "step": lambda self, c: None})
            h = Harness(agent)
            with self.assertRaisesRegex(ValueError, f"has no {kind} 'x'; it has \\['{port}'\\]"):
                (h.call if kind == "service" else h.requests)("x")
        with self.assertRaisesRegex(RuntimeError, "max_in_flight 65: give 1 to 64"):
            Harness(type("TooMany", (nerve.Agent,), {
                "period": 0.1, "step": lambda self, c: None,
                "new": lambda self, s: s.client("p", "nerve::Tick", "nerve::Tick", max_in_flight=65)}))


if __name__ == "__main__":
    unittest.main()
