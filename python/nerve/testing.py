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
"""

from __future__ import annotations

import json

import numpy as np

from . import Agent, Message, Meta, _kind_of, _native
from . import seq as _seq

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
