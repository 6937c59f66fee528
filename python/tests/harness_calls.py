"""Calls in the Python test harness (``nerve.testing.Harness``): the test
calls the service of ``py_caller.PyServer`` and its own ``serve`` answers
at its step; the calls of ``py_caller.PyClient`` come to the test, which
answers them, ends one as the server gone and lets one time out on the
harness's clock.

Not named ``test_*``: run by tests/tests/python_calls.rs
(``python -m unittest harness_calls``), in the test's own process.
"""

import unittest

from nerve.testing import Harness
from py_caller import PyClient, PyServer


class HarnessCalls(unittest.TestCase):
    def test_the_test_calls_a_python_service(self):
        h = Harness(PyServer)
        a = h.ask("plan", seq=21, stamp_ns=5)
        self.assertEqual((float(a.value), int(a.stamp_ns)), (42.0, 5))
        ids = [h.call("plan", seq=i) for i in (1, 2)]
        self.assertEqual(h.answers("plan"), [], "nothing before the step")
        h.step()
        got = [(f.id, float(f.answer.value)) for f in h.answers("plan")]
        self.assertEqual(got, [(ids[0], 2.0), (ids[1], 4.0)])
        self.assertEqual(h.agent.plan.answered, 3)
        [report] = h.output("report")[-1:]
        self.assertEqual(int(report.answered), 3)
        with self.assertRaisesRegex(ValueError, "no service 'nope'"):
            h.call("nope", seq=1)

    def test_the_test_calls_a_python_service_of_sequence_answers(self):
        h = Harness(PyServer)
        a = h.ask("plans", seq=3, stamp_ns=7)
        self.assertEqual((int(a.header.seq), len(a)), (3, 3))
        self.assertEqual(a.items["value"].tolist(), [0.0, 1.0, 2.0])
        self.assertEqual(set(a.items["stamp_ns"].tolist()), {7})
        self.assertEqual(len(h.ask("plans", seq=0)), 0)
        # past the service's 500: its caller is refused, the step says why
        id = h.call("plans", seq=501)
        h.step()
        [f] = h.answers("plans")
        self.assertEqual((f.id, f.error.kind if f.error else None), (id, "refused_too_long"))

    def test_the_agents_calls_come_to_the_test_which_answers_them(self):
        h = Harness(PyClient)
        h.step()
        [(first, req)] = h.requests("planner")
        self.assertEqual(int(req.seq), 1)
        h.answer("planner", first, value=2.0)
        h.step()
        self.assertEqual((h.agent.counts["answered"], h.agent.counts["wrong"]), (1, 0))
        [(second, req)] = h.requests("planner")
        self.assertEqual(int(req.seq), 2)
        h.answer("planner", second, value=99.0)
        h.step()
        self.assertEqual(h.agent.counts["wrong"], 1)
        [(third, _)] = h.requests("planner")
        h.answer("planner", third, error="server_gone")
        h.step()
        self.assertEqual(h.agent.counts["gone"], 1)
        # unanswered: it times out after 400 ms on the harness's clock
        [(fourth, _)] = h.requests("planner")
        h.advance(0.4)
        self.assertEqual(h.agent.counts["timed_out"], 1)
        with self.assertRaisesRegex(RuntimeError, "not in flight"):
            h.answer("planner", fourth, value=8.0)
        self.assertEqual(h.agent.counts["sent"], 5)


if __name__ == "__main__":
    unittest.main()
