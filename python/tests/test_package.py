"""Tests of the nerve Python package in the test's own process: layouts
and the harness. Run by tests/tests/python.rs (`python -m unittest` here)."""

import os
import sys
import time
import unittest

import numpy as np

import nerve
from nerve.testing import Harness

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "examples"))
from scale import Scale  # noqa: E402


class Layouts(unittest.TestCase):
    def test_a_layout_is_laid_out_as_repr_c(self):
        p = nerve.payload("test::Mixed", [("a", "u8"), ("b", "f64"), ("c", ("u16", 3)), ("d", "bool")])
        self.assertEqual(p.size, 24)  # a@0, b@8, c@16..22, d@22, rounded to 8
        self.assertEqual([p.dtype.fields[n][1] for n in ("a", "b", "c", "d")], [0, 8, 16, 22])
        nested = nerve.payload("test::Nested", [("head", "u8"), ("m", p)])
        self.assertEqual(nested.dtype.fields["m"][1], 8)

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


if __name__ == "__main__":
    unittest.main()
