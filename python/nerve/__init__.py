"""nerve agents in Python.

An agent is a class with ``new`` (declare ports and parameters) and ``step``
(one cycle of its task), run by ``nerve.run``::

    import nerve

    class Doubler(nerve.Agent):
        kind = "doubler"
        period = None                # event-driven; seconds for a periodic task

        def new(self, setup):
            self.ticks = setup.input("tick", "nerve::Tick")
            self.out = setup.output("value", "nerve::Scalar")
            self.gain = setup.param("gain", 2.0)

        def step(self, ctx):
            for tick in self.ticks.drain():
                self.out.send(value=tick.seq * self.gain.get(), stamp_ns=ctx.now_ns)

    if __name__ == "__main__":
        nerve.run(Doubler)

The agent is a nerve agent like any other: the SDK's runtime (``_native``,
the Rust SDK) registers it with the router, rewires its inputs, changes its
period, suspends and resumes it, reports its statistics and stops it
cleanly; ``nerve start``, launch files, ``nerve ps`` and ``nerve echo``
treat it as they treat a Rust agent.

Payload types are layouts: a built-in type by name (``"nerve::Tick"``), or
one written here with ``nerve.payload`` (the layout a ``#[repr(C)]`` Rust
struct of those fields has, so a Rust agent built with that struct reads it
in place). Messages are numpy views of the samples in shared memory: a
received message is read in place, a loaned one written in place.

A loaned message is the sender's until ``out.send(msg)``; after it, its
memory is the readers' (or, in a test, freed), and ``msg.field`` raises
instead of touching it. A view taken from it (``msg.array``, an array
field, a nested struct) must not outlive it: ``send`` raises
``BufferError`` while one lives, as a ``bytearray`` refuses to resize;
``del`` the view or keep a ``.copy()``.
"""

from __future__ import annotations

import json
import re
import sys
from typing import NamedTuple

import numpy as np

from . import _native

__all__ = ["Agent", "Payload", "payload", "builtin", "run", "Message", "Meta", "Input", "Output", "Setup",
           "Sequence", "sequence", "SeqMessage", "SeqInput", "SeqOutput",
           "Server", "Client", "CallError", "CallRefused", "Finished"]

_PRIMITIVES = {
    "u8": "<u1", "u16": "<u2", "u32": "<u4", "u64": "<u8",
    "i8": "<i1", "i16": "<i2", "i32": "<i4", "i64": "<i8",
    "f32": "<f4", "f64": "<f8", "bool": "?",
}


def _dtype(schema: dict) -> np.dtype:
    """The numpy dtype of a layout (a schema, as the SDK writes it)."""
    kind = schema["kind"]
    if "primitive" in kind:
        return np.dtype(_PRIMITIVES[kind["primitive"]["primitive"]])
    if "array" in kind:
        return np.dtype((_dtype(kind["array"]["element"]), (kind["array"]["len"],)))
    if "string" in kind:
        cap = kind["string"]["capacity"]
        return np.dtype({"names": ["len", "bytes"], "formats": ["<u4", ("u1", (cap,))],
                         "offsets": [0, 4], "itemsize": schema["size"]})
    fields = kind["struct"]["fields"]
    return np.dtype({
        "names": [f["name"] for f in fields],
        "formats": [_dtype(f["schema"]) for f in fields],
        "offsets": [f["offset"] for f in fields],
        "itemsize": schema["size"],
    }, metadata={"nerve": schema["type_name"]})


class Payload:
    """A payload type: its name, its layout (``schema``) and numpy ``dtype``."""

    def __init__(self, schema_json: str):
        # checked first (ValueError saying what is wrong): a layout from
        # outside never reaches numpy or a port unchecked
        self.fingerprint = _native.fingerprint(schema_json)
        self.schema_json = schema_json
        self.schema = json.loads(schema_json)
        self.type_name = self.schema["type_name"]
        self.size = self.schema["size"]
        self.dtype = _dtype(self.schema)

    def __repr__(self) -> str:
        return f"Payload({self.type_name!r}, {self.size} B, fingerprint {self.fingerprint:#018x})"


def _field_schema(t) -> str:
    if isinstance(t, Payload):
        return t.schema_json
    if isinstance(t, tuple) and len(t) == 2:
        return _native.array_schema(_field_schema(t[0]), int(t[1]))
    if isinstance(t, str):
        if t in _PRIMITIVES:
            return _native.primitive_schema(t)
        return builtin(t).schema_json
    raise TypeError(f"a field type {t!r}: give a primitive name ('u8' ... 'f64', 'bool'), "
                    "(type, length) for an array, or a nerve.Payload")


def payload(type_name: str, fields):
    """A payload type laid out as the ``#[repr(C)]`` Rust struct of ``fields``
    (``[(name, type), ...]`` in order; a type is ``"u8"`` ... ``"f64"``,
    ``"bool"``, ``(type, length)`` for an array, a built-in type's name or
    another ``Payload``). Give it the Rust type's stable name
    (``#[payload(name = ...)]``) to talk to agents built with it.

    The last field may be a sequence of any length, ``("items", [element])``:
    the result is then the ``nerve.sequence`` of ``element`` after a header
    named ``type_name`` of the other fields (Rust's ``Seq<Element, TypeName>``).
    """
    fields = list(fields)
    if fields and isinstance(fields[-1][1], list):
        name, trailing = fields[-1]
        if name != "items" or len(trailing) != 1:
            raise TypeError(f"{type_name}: a trailing sequence is written (\"items\", [element]), "
                            f"not ({name!r}, {trailing!r})")
        header = payload(type_name, fields[:-1]) if len(fields) > 1 else None
        return sequence(trailing[0], header)
    for name, t in fields:
        if isinstance(t, list):
            raise TypeError(f"{type_name}.{name}: only the last field may be a sequence ((\"items\", [element]))")
    return Payload(_native.struct_schema(type_name, [(n, _field_schema(t)) for n, t in fields]))


_BUILTIN: dict = {}


def builtin(type_name: str) -> Payload:
    """The built-in payload type ``type_name`` (``nerve::Tick``, ...)."""
    found = _BUILTIN.get(type_name)
    if found is None:
        schema = _native.builtin_schema(type_name)
        if schema is None:
            known = ", ".join(sorted(_native.builtin_types()))
            raise ValueError(f"no built-in payload type {type_name!r} (built in: {known}); "
                             "declare its layout with nerve.payload(name, fields)")
        found = _BUILTIN[type_name] = Payload(schema)
    return found


def _payload_of(t) -> Payload:
    return t if isinstance(t, Payload) else builtin(t)


class Meta(NamedTuple):
    """Who sent a message, its number on the sending port and when it was sent."""

    sender: str
    seq: int
    stamp_ns: int


class Message:
    """One sample of a payload, viewed in place: ``msg.field`` reads a field
    (an array field is a numpy view, no copy), ``msg.field = v`` writes one
    (a loaned message only). ``msg.meta`` says who sent it (``sender``,
    ``seq``, ``stamp_ns``) for a received one. A received message keeps its
    sample in shared memory while it lives: an input lends two per source
    at once, so keep ``msg.copy()`` to hold more.

    A loaned message is spent by ``send``: its fields then raise
    ``RuntimeError`` (the memory is the readers'). A view of it
    (``msg.array``, an array field, a nested struct) keeps it from being
    sent (``BufferError``) while it lives."""

    __slots__ = ("_a", "meta", "_loan", "_dtype")

    def __init__(self, array, meta=None, loan=None):
        object.__setattr__(self, "_a", array)
        object.__setattr__(self, "meta", meta)
        object.__setattr__(self, "_loan", loan)
        object.__setattr__(self, "_dtype", array.dtype)

    def _array(self):
        a = self._a
        if a is None:
            raise RuntimeError(f"this {self.type_name} message was sent: its memory is the readers' now; "
                               "loan a new one (out.loan()), or keep msg.copy() before sending")
        return a

    def __getattr__(self, name):
        a = self._array()
        try:
            return a[name][0]
        except (ValueError, KeyError, IndexError):
            raise AttributeError(f"{self.type_name} has no field {name!r} "
                                 f"(fields: {', '.join(a.dtype.names or ())})") from None

    def __setattr__(self, name, value):
        a = self._array()
        try:
            a[name] = value
        except (ValueError, KeyError) as e:
            if name not in (a.dtype.names or ()):
                raise AttributeError(f"{self.type_name} has no field {name!r}") from None
            raise ValueError(f"{self.type_name}.{name}: {e} (a received message is read-only; "
                             "loan one from an output to write)") from None

    __getitem__ = __getattr__

    def __setitem__(self, name, value):
        self.__setattr__(name, value)

    @property
    def array(self) -> np.ndarray:
        """The sample as a one-element numpy structured array (a view: a
        loaned message is not sent while it lives)."""
        return self._array()

    @property
    def type_name(self) -> str:
        return (self._dtype.metadata or {}).get("nerve", "payload")

    @property
    def sent(self) -> bool:
        """Whether this loaned message was sent (its fields are gone)."""
        return self._a is None

    def copy(self) -> "Message":
        """A copy that holds no shared memory (nor the sample: its slot is
        the sender's again once the original is dropped)."""
        m = self.meta
        return Message(self._array().copy(), None if m is None else Meta(m.sender, m.seq, m.stamp_ns))

    def to_dict(self) -> dict:
        """The fields as Python values (arrays as lists)."""
        a = self._array()
        return {n: a[n][0].tolist() for n in a.dtype.names}

    def __repr__(self) -> str:
        if self._a is None:
            return f"Message({self.type_name}, sent)"
        return f"Message({self.to_dict()})"


class Input:
    """An input port; the router connects it to output ports of its type."""

    def __init__(self, native, payload: Payload):
        self._n = native
        self.payload = payload
        self._dtype = payload.dtype

    def take(self):
        """The next waiting message, or None."""
        r = self._n.take()
        if r is None:
            return None
        return Message(np.frombuffer(r, dtype=self._dtype, count=1), r)

    def drain(self):
        """Every waiting message, in turn (a generator: take each before the next)."""
        take = self.take
        while True:
            m = take()
            if m is None:
                return
            yield m

    def latest(self):
        """The newest waiting message (the older ones are dropped), or None."""
        newest = None
        for m in self.drain():
            newest = m.copy() if newest is None or m.meta.stamp_ns >= newest.meta.stamp_ns else newest
        return newest

    @property
    def sources(self) -> int:
        """How many output ports feed it now."""
        return self._n.sources()


class Output:
    """An output port."""

    def __init__(self, native, payload: Payload):
        self._n = native
        self.payload = payload
        self._dtype = payload.dtype

    def loan(self, zeroed: bool = True) -> Message:
        """A message to write in place, then ``send``; ``zeroed=False`` skips
        zeroing it (write every field a reader looks at)."""
        loan = self._n.loan(zeroed)
        return Message(np.frombuffer(loan, dtype=self._dtype, count=1), None, loan)

    def send(self, message=None, /, **fields) -> None:
        """Sends a loaned ``message``; or a new one made of ``fields``
        (``out.send(value=1.5, stamp_ns=...)``, the rest zero); or a copy of
        ``message`` when it is another message, a dict or bytes."""
        if message is not None and isinstance(message, Message) and message._loan is not None and not fields:
            self._send_loaned(message)
            return
        if isinstance(message, (bytes, bytearray, memoryview)) and not fields:
            self._n.send_bytes(message)
            return
        m = self.loan()
        if isinstance(message, Message):
            m._a[...] = message._array()
        elif isinstance(message, dict):
            for k, v in message.items():
                setattr(m, k, v)
        elif message is not None:
            raise TypeError(f"send takes a Message, a dict, bytes or fields, not {type(message).__name__}")
        for k, v in fields.items():
            setattr(m, k, v)
        self._send_loaned(m)

    def _send_loaned(self, m: Message) -> None:
        """Sends a loaned message: drops its own view first (the loan is not
        sent while a view lives), and gives the view back if the send fails."""
        a = m._array()
        object.__setattr__(m, "_a", None)
        del a
        try:
            self._n.send(m._loan)
        except BaseException:
            if not m._loan.sent:
                object.__setattr__(m, "_a", np.frombuffer(m._loan, dtype=m._dtype, count=1))
            raise

    @property
    def service(self) -> str:
        return self._n.service


from .seq import Sequence, sequence, SeqMessage, SeqInput, SeqOutput  # noqa: E402 (they use the above)
from .call import CallError, CallRefused, Client, Finished, Server  # noqa: E402


class Setup:
    """What ``Agent.new`` declares ports and parameters on."""

    def __init__(self, native):
        self._n = native
        # what was declared, by port: the test harness reads them
        self.inputs: dict = {}
        self.outputs: dict = {}
        self.services: dict = {}
        self.clients: dict = {}

    @property
    def name(self) -> str:
        return self._n.name

    @property
    def robot(self) -> str:
        return self._n.robot

    @property
    def args(self) -> list:
        """The arguments after ``--`` on the agent's command line."""
        return self._n.args

    def input(self, port: str, type) -> Input:
        """Declares input ``port`` of payload ``type`` (a name, a ``Payload``
        or a ``nerve.sequence``)."""
        if isinstance(type, Sequence):
            made = SeqInput(self._n.input(port, type.schema_json), type)
            self.inputs[port] = type
            return made
        p = _payload_of(type)
        made = Input(self._n.input(port, p.schema_json), p)
        self.inputs[port] = p
        return made

    def output(self, port: str, type, *, max_len: int | None = None) -> Output:
        """Declares output ``port`` of payload ``type`` (a name or a
        ``Payload``; or a ``nerve.sequence``, which takes ``max_len``)."""
        if isinstance(type, Sequence):
            if max_len is None:
                raise TypeError(f"output {port!r} of {type.type_name}: give max_len, the most elements a sample holds")
            made = SeqOutput(_native.output_seq(self._n, port, type.schema_json, int(max_len)), type)
            self.outputs[port] = type
            return made
        if max_len is not None:
            raise TypeError(f"output {port!r}: max_len is for a sequence (nerve.sequence), not {type!r}")
        p = _payload_of(type)
        made = Output(self._n.output(port, p.schema_json), p)
        self.outputs[port] = p
        return made

    def input_seq(self, port: str, element, header=None) -> "SeqInput":
        """Declares input ``port`` of samples of ``header`` then any number
        of ``element`` (as Rust's ``setup.input_seq::<T, H>(port)``)."""
        return self.input(port, sequence(element, header))

    def output_seq(self, port: str, element, header=None, *, max_len: int) -> "SeqOutput":
        """Declares output ``port`` of samples of ``header`` then at most
        ``max_len`` of ``element`` (as Rust's ``setup.output_seq::<T, H>(port, max_len)``)."""
        return self.output(port, sequence(element, header), max_len=max_len)

    def serve(self, port: str, request, response, *, max_len: int | None = None) -> "Server":
        """Declares service ``port``: requests of payload ``request``
        answered with ``response`` (names or ``Payload``s, or a
        ``nerve.sequence`` of at most ``max_len`` elements), in this agent's
        task, which a request wakes like an input (as Rust's
        ``setup.serve::<Req, Resp>(port)`` and ``setup.serve_seq::<Req, T,
        H>(port, max_len)``)."""
        req = _payload_of(request)
        if isinstance(response, Sequence):
            if max_len is None:
                raise TypeError(f"service {port!r} answering {response.type_name}: give max_len, "
                                "the most elements an answer holds")
            resp = response
            native = _native.serve(self._n, port, req.schema_json, resp.schema_json, int(max_len))
        elif max_len is not None:
            raise TypeError(f"service {port!r}: max_len is for a sequence answer (nerve.sequence), not {response!r}")
        else:
            resp = _payload_of(response)
            native = _native.serve(self._n, port, req.schema_json, resp.schema_json)
        made = Server(native, req, resp)
        self.services[port] = (req, resp)
        return made

    def client(self, port: str, request, response, *, timeout: float = 1.0, max_in_flight: int = 16) -> "Client":
        """Declares client ``port`` of a service of ``request`` answered with
        ``response``; the router wires it (``nerve connect AGENT/PORT
        SERVER/SERVICE``). Each call waits at most ``timeout`` seconds for
        its answer; at most ``max_in_flight`` (1 to 64) are in flight.
        ``response`` may be a ``nerve.sequence``: answers are then
        ``SeqMessage``s."""
        req = _payload_of(request)
        resp = response if isinstance(response, Sequence) else _payload_of(response)
        native = _native.client(self._n, port, req.schema_json, resp.schema_json, float(timeout), int(max_in_flight))
        self.clients[port] = (req, resp)
        return Client(native, req, resp)

    def param(self, key: str, default, *, min=None, max=None):
        """Declares parameter ``key`` (float, int, bool or str, as ``default``);
        ``.get()`` reads the value ``nerve param set`` last set.

        A float or int parameter may have inclusive bounds ``min`` and ``max``
        (either or both): a value outside them is refused at start
        (``--param``), by ``nerve param set`` and by the Harness, with a
        message naming the range (``gain is in [0, 10]``) that ``nerve param
        list`` shows. A default outside its own bounds is a ValueError."""
        return self._n.param(key, default, min, max)


class Agent:
    """The template: fill in ``new`` and ``step``.

    ``kind``: what ``nerve ps`` shows (default: the class name, lower case);
    ``period``: seconds between steps of a periodic task, None (the default)
    for an event-driven task woken by its inputs.
    """

    kind: str | None = None
    period: float | None = None

    def new(self, setup: Setup) -> None:
        """Declares ports and parameters; open devices in ``start``."""

    def start(self, ctx) -> None:
        """Once, in the task thread, before the first step."""

    def step(self, ctx) -> None:
        """One cycle of the task. ``ctx``: ``now_ns``, ``cycle``, ``period``,
        ``deadline_ns``, ``woken_by``, ``has_new(input)``, ``request_stop()``."""
        raise NotImplementedError(f"{type(self).__name__}.step")

    def stop(self, ctx) -> None:
        """Once, in the task thread, after the last step."""

    # what the SDK calls
    def _nerve_new(self, native):
        setup = Setup(native)
        self.new(setup)
        self._nerve_ports = (setup.inputs, setup.outputs)
        self._nerve_calls = (setup.services, setup.clients)

    def _nerve_start(self, ctx):
        self.start(ctx)

    def _nerve_step(self, ctx):
        self.step(ctx)

    def _nerve_stop(self, ctx):
        self.stop(ctx)


def _kind_of(cls) -> str:
    if cls.kind:
        return cls.kind
    return re.sub(r"(?<!^)(?=[A-Z])", "-", cls.__name__).lower()


def run(agent_class, argv=None):
    """Runs ``agent_class`` as a nerve agent with the common command line
    (``--robot``, ``--name``, ``--period``, ``--daemon``, ``--describe``,
    ``--param KEY=VALUE``, ...: ``--help`` lists them) and ends the process
    with its exit status."""
    if not (isinstance(agent_class, type) and issubclass(agent_class, Agent)):
        raise TypeError("nerve.run takes a subclass of nerve.Agent")
    argv = sys.argv[1:] if argv is None else list(argv)
    period = agent_class.period
    code = _native.run(agent_class, _kind_of(agent_class), None if period is None else float(period), argv)
    sys.stdout.flush()
    raise SystemExit(code)
