"""Testing a Python agent in the test's own process.

``Harness(MyAgent)`` runs the agent's own ``new`` and ``start`` with its
ports bound to in-memory queues (the Rust SDK's
``agent_sdk::testing::Harness``): no router, no shared memory, no sleeping.
The test sends messages, steps the agent (a periodic agent's clock jumps to
its next deadline) or moves its clock on, and reads what it sent::

    from nerve.testing import Harness

    h = Harness(Scale, params={"gain": "3"})
    h.send("tick", seq=7, stamp_ns=h.now_ns)
    h.step()
    [v] = h.output("value")
    assert v.value == 21

Parameters (``set_param``, ``param``), the period (``set_period``),
``suspend``/``resume``, ``input_stats`` and ``stop`` behave as their
``nerve`` commands do on a running agent.

Calls work as on a running agent. The test calls a service the agent
serves, and the agent's own ``serve`` answers it at its next step; the
calls the agent makes through a client come to the test, which answers
them, and the agent takes the answer at its next step::

    answer = h.ask("double", value=21.0)       # call, step, the answer
    [(id, req)] = h.requests("sensor")         # what the agent asked
    h.answer("sensor", id, value=7.0)          # its answer, taken at the next step

A call's timeout counts on the harness's clock (``advance``).
"""

from __future__ import annotations

import json

import numpy as np

from . import Agent, Message, Meta, _kind_of, _native
from . import seq as _seq
from .call import CallError, Finished, _answer_bytes, _answer_of, _bytes_of

__all__ = ["Harness"]


class Harness:
    """An agent class run in this process; see the module."""

    def __init__(self, agent_class, *, name=None, args=(), params=None, period=None, suspended=False):
        if not (isinstance(agent_class, type) and issubclass(agent_class, Agent)):
            raise TypeError("Harness takes a subclass of nerve.Agent")
        p = agent_class.period
        self._h = _native.Harness(
            agent_class,
            _kind_of(agent_class),
            None if p is None else float(p),
            name,
            [str(a) for a in args],
            [(str(k), str(v)) for k, v in (params or {}).items()],
            None if period is None else float(period),
            bool(suspended),
        )
        self.agent = self._h.agent
        self._inputs, self._outputs = self.agent._nerve_ports
        self._services, self._clients = self.agent._nerve_calls

    def send(self, input: str, message=None, /, *, sender: str = "test", **fields) -> None:
        """Queues a message on ``input`` from agent ``sender``: ``fields``
        (the rest zero), a dict, a ``Message`` or bytes of the layout; for
        a sequence input, ``header=`` (a dict or Message) and ``items=``,
        or a ``SeqMessage``."""
        try:
            payload = self._inputs[input]
        except KeyError:
            raise ValueError(f"the agent has no input {input!r}; it has {sorted(self._inputs)}") from None
        if isinstance(message, (bytes, bytearray, memoryview)) and not fields:
            data = bytes(message)
        elif isinstance(payload, _seq.Sequence):
            # a sequence: a SeqMessage, or header= (dict or Message) and items=
            unknown = set(fields) - {"header", "items"}
            if unknown:
                raise TypeError(f"a {payload.type_name} message takes header= and items=, not {sorted(unknown)}")
            data = _seq.encoded(payload, message, fields.get("header"), fields.get("items"))
        else:
            a = np.zeros(1, dtype=payload.dtype)
            if isinstance(message, Message):
                a[...] = message.array
            elif isinstance(message, dict):
                fields = {**message, **fields}
            elif message is not None:
                raise TypeError(f"send takes a Message, a dict, bytes or fields, not {type(message).__name__}")
            m = Message(a)
            for k, v in fields.items():
                setattr(m, k, v)
            data = a.tobytes()
        self._h.send_bytes(input, sender, data)

    def output(self, port: str) -> list:
        """What output ``port`` sent since the last call, oldest first (copies,
        each with ``meta``)."""
        try:
            payload = self._outputs[port]
        except KeyError:
            raise ValueError(f"the agent has no output {port!r}; it has {sorted(self._outputs)}") from None
        sent = self._h.output_bytes(port)
        if isinstance(payload, _seq.Sequence):
            return [_seq.decoded(data, payload, Meta(sender, seq, stamp)) for sender, seq, stamp, data in sent]
        return [
            Message(np.frombuffer(data, dtype=payload.dtype, count=1).copy(), Meta(sender, seq, stamp))
            for sender, seq, stamp, data in sent
        ]

    def _call_port(self, kind: str, port: str):
        ports = self._services if kind == "service" else self._clients
        try:
            return ports[port]
        except KeyError:
            raise ValueError(f"the agent has no {kind} {port!r}; it has {sorted(ports)}") from None

    def call(self, service: str, message=None, /, **fields) -> int:
        """Calls service ``service`` of the agent with a request (a Message,
        a dict, bytes or ``fields``, the rest zero); the agent's next step
        answers it (``answers``). Returns the call's id."""
        req, _ = self._call_port("service", service)
        if message is None:
            message = fields
        elif fields:
            raise TypeError("call takes a message or fields, not both")
        return self._h.call_bytes(service, _bytes_of(req, message, "a request"))

    def answers(self, service: str) -> list:
        """The answers service ``service`` gave the test's calls since the
        last look, oldest first, as ``Finished(id, answer, error)``."""
        _, resp = self._call_port("service", service)
        out = []
        for id, data, kind, message in self._h.answers_bytes(service):
            if data is None:
                out.append(Finished(id, None, CallError(kind, message)))
            else:
                out.append(Finished(id, _answer_of(resp, data), None))
        return out

    def ask(self, service: str, message=None, /, **fields):
        """Calls ``service``, runs one step and returns the answer (a
        Message). Raises the call's ``CallError``, or RuntimeError if the
        step did not answer it."""
        id = self.call(service, message, **fields)
        self.step()
        mine = [f for f in self.answers(service) if f.id == id]
        if not mine:
            raise RuntimeError(f"service {service!r}: call {id} was not answered at the agent's step "
                               "(does its step serve the port?)")
        if mine[0].error is not None:
            raise mine[0].error
        return mine[0].answer

    def requests(self, client: str) -> list:
        """The calls the agent made through ``client`` since the last look,
        oldest first: ``(id, request)``, the request a Message."""
        req, _ = self._call_port("client", client)
        return [(id, Message(np.frombuffer(data, dtype=req.dtype, count=1).copy()))
                for id, data in self._h.requests_bytes(client)]

    def answer(self, client: str, id: int, message=None, /, *, error: str | None = None, **fields) -> None:
        """Answers the agent's call ``id`` through ``client`` (a Message, a
        dict, bytes or ``fields``), or ends it with ``error``
        (``"server_gone"``, ``"timed_out"``); the agent takes it at its next
        step. RuntimeError if the call is not in flight (it timed out)."""
        _, resp = self._call_port("client", client)
        if error is not None:
            if message is not None or fields:
                raise TypeError("answer takes an answer or an error, not both")
            self._h.answer_bytes(client, int(id), None, error)
            return
        if message is None:
            message = fields
        elif fields:
            raise TypeError("answer takes a message or fields, not both")
        self._h.answer_bytes(client, int(id), _answer_bytes(resp, message))

    def step(self) -> None:
        """Runs one step; a step's exception is raised here."""
        self._h.step()

    def advance(self, seconds: float) -> int:
        """Moves the clock on, running every step due; returns how many ran."""
        return self._h.advance(float(seconds))

    def run_cycles(self, n: int) -> None:
        self._h.run_cycles(int(n))

    def set_param(self, key: str, value) -> None:
        """As ``nerve param set``; ValueError with its refusal."""
        self._h.set_param(key, str(value))

    def param(self, key: str) -> str:
        return self._h.param(key)

    def set_period(self, seconds: float) -> None:
        self._h.set_period(float(seconds))

    def suspend(self) -> None:
        self._h.suspend()

    def resume(self) -> None:
        self._h.resume()

    def input_stats(self) -> list:
        """Per input and source: received, dropped, last age (``nerve ps --json``)."""
        return json.loads(self._h.input_stats())

    def stop(self) -> None:
        """Runs the agent's ``stop``."""
        self._h.stop()

    @property
    def now_ns(self) -> int:
        return self._h.now_ns

    @property
    def cycles(self) -> int:
        return self._h.cycles

    @property
    def errors(self) -> int:
        return self._h.errors

    @property
    def stop_requested(self) -> bool:
        return self._h.stop_requested

    @property
    def period(self):
        return self._h.period
