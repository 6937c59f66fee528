"""Calls between agents (issue 42): a service the agent answers and a
client it calls through, what ROS 2 calls services.

    def new(self, setup):
        self.plan = setup.serve("plan", Goal, Path)          # answered in this agent's task
        self.planner = setup.client("planner", Goal, Path, timeout=1.0)

    def step(self, ctx):
        self.plan.serve(lambda goal: {"x": goal.x * 2})      # every waiting request
        id = self.planner.call(x=1.0, y=2.6)                 # returns at once
        for done in self.planner.drain():                    # finished calls, oldest first
            if done.ok:
                print(done.id, done.answer.x)
            else:
                print(done.id, done.error.kind, done.error)  # timed_out, server_gone, unwired

A request wakes the server's task like an input (``ctx.woken_by`` names
the service). The router wires a client to a service as it wires an input
to an output (``nerve connect a/planner b/plan``, ``[[connect]]``),
checking both types; ``nerve call b/plan '{"x": 1}'`` calls a service from
the terminal. Requests are fixed-size payloads; answers are fixed-size
payloads or sequences (``setup.serve("plan", Goal, nerve.sequence(Point,
PathHeader), max_len=500)``, answered with ``(header, items)``: a dict or
Message and a numpy array or list; the client's answer is a
``SeqMessage``), the same layouts as a Rust agent's ``setup.serve::<Req,
Resp>`` and ``setup.serve_seq::<Req, T, H>``. Both are copied (a call is
small).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from . import _native

CallRefused = _native.CallRefused


class CallError(RuntimeError):
    """Why a call has no answer: ``kind`` is ``timed_out`` (no answer within
    the client's timeout), ``server_gone`` (the server died or let go with
    the call in flight), ``unwired`` (the client was disconnected) or
    ``malformed``/``failed``. A timed-out or gone call may have been
    carried out (``maybe_carried_out``): do not send it again blindly."""

    def __init__(self, kind: str, message: str):
        super().__init__(message)
        self.kind = kind

    @property
    def maybe_carried_out(self) -> bool:
        return self.kind in ("timed_out", "server_gone", "unwired")


class Finished(NamedTuple):
    """A finished call: its ``id`` (what ``call`` returned), its ``answer``
    (a ``nerve.Message``) or its ``error`` (a ``CallError``)."""

    id: int
    answer: object
    error: CallError | None

    @property
    def ok(self) -> bool:
        return self.error is None


def _answer_bytes(response, value) -> bytes:
    """An answer's bytes: for a sequence a ``SeqMessage``, a ``(header,
    items)`` pair or a dict ``{"header": ..., "items": ...}`` (or bytes of a
    whole sample); for a fixed payload what ``_bytes_of`` takes."""
    from .seq import SeqMessage, Sequence, encoded

    if not isinstance(response, Sequence):
        return _bytes_of(response, value, "an answer")
    if isinstance(value, (bytes, bytearray, memoryview)):
        return bytes(value)
    if isinstance(value, SeqMessage):
        return encoded(response, value)
    if isinstance(value, tuple) and len(value) == 2:
        return encoded(response, None, value[0], value[1])
    if isinstance(value, dict) and set(value) <= {"header", "items"}:
        return encoded(response, None, value.get("header"), value.get("items"))
    raise TypeError(f"an answer of {response.type_name} is (header, items), a dict of header= and items=, "
                    f"a SeqMessage or bytes, not {type(value).__name__}")


def _answer_of(response, data: bytes):
    """A finished call's answer over a copy of ``data``: a ``SeqMessage``
    for a sequence, else a ``nerve.Message``."""
    from . import Message
    from .seq import Sequence, decoded

    if isinstance(response, Sequence):
        return decoded(data, response)
    return Message(np.frombuffer(data, dtype=response.dtype, count=1).copy())


def _bytes_of(payload, value, what: str) -> bytes:
    """The bytes of ``value`` laid out as ``payload``: a Message, a dict of
    fields (the rest zero), or bytes of exactly its size."""
    from . import Message

    if isinstance(value, (bytes, bytearray, memoryview)):
        return bytes(value)
    a = np.zeros(1, dtype=payload.dtype)
    if isinstance(value, Message):
        a[...] = value.array
    elif isinstance(value, dict):
        m = Message(a)
        for k, v in value.items():
            setattr(m, k, v)
    else:
        raise TypeError(f"{what} of {payload.type_name} is a nerve.Message, a dict of its fields or bytes, "
                        f"not {type(value).__name__}")
    return a.tobytes()


class Server:
    """A service the agent answers: requests of ``request`` answered with ``response``."""

    def __init__(self, native, request, response):
        self._n = native
        self.request = request
        self.response = response

    def serve(self, answer, max: int = 64) -> int:
        """Answers each waiting request (at most ``max``; the rest wait for
        the next step) with ``answer(request)``: ``request`` is a
        ``nerve.Message``, and ``answer`` returns a Message, a dict of the
        answer's fields (the rest zero) or bytes; for a sequence answer,
        ``(header, items)`` (see ``_answer_bytes``). Returns how many were
        answered. An exception of ``answer`` is raised here; its request
        goes unanswered (its caller sees ``server_gone``). A sequence longer
        than the service's ``max_len`` is refused (its caller sees
        ``refused_too_long``) and raised here (ValueError) after the others are answered."""
        from . import Message

        req_dtype, resp = self.request.dtype, self.response

        def one(data: bytes) -> bytes:
            return _answer_bytes(resp, answer(Message(np.frombuffer(data, dtype=req_dtype, count=1))))

        return self._n.serve(int(max), one)

    @property
    def answered(self) -> int:
        """How many requests it answered so far."""
        return self._n.answered

    @property
    def service(self) -> str:
        return self._n.service


class Client:
    """A client of a service of ``request`` answered with ``response``,
    once the router wired it to one."""

    def __init__(self, native, request, response):
        self._n = native
        self.request = request
        self.response = response

    def call(self, message=None, /, **fields) -> int:
        """Sends a request (a Message, a dict, bytes, or ``fields``, the
        rest zero) and returns its id at once; the answer comes from
        ``take``. Raises ``CallRefused``, with nothing sent, when the
        client is not wired, no server answers, or ``max_in_flight`` calls
        are in flight."""
        if message is None:
            message = fields
        elif fields:
            raise TypeError("call takes a message or fields, not both")
        return self._n.call(_bytes_of(self.request, message, "a request"))

    def take(self) -> Finished | None:
        """The next finished call, oldest first, or None (never waits)."""
        from . import Message

        got = self._n.take()
        if got is None:
            return None
        id, data, kind, message = got
        if data is None:
            return Finished(id, None, CallError(kind, message))
        return Finished(id, _answer_of(self.response, data), None)

    def drain(self):
        """Every finished call, oldest first."""
        while True:
            f = self.take()
            if f is None:
                return
            yield f

    @property
    def in_flight(self) -> int:
        return self._n.in_flight

    @property
    def wired(self) -> bool:
        """Whether the router wired it to a service."""
        return self._n.wired

    @property
    def timeout(self) -> float:
        return self._n.timeout

    @property
    def max_in_flight(self) -> int:
        return self._n.max_in_flight
