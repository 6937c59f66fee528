"""Sequences: payloads of any length (issue 42).

A sequence sample is a fixed header followed by any number of a fixed-size
element, the layout of a Rust agent's ``Seq<T, H>``
(``setup.output_seq::<T, H>(port, max_len)``)::

    Detection = nerve.payload("acme::Detection", [("x", "f32"), ("y", "f32"), ("id", "u32")])
    Header = nerve.payload("acme::DetectionsHeader", [("frame", "u64"), ("count", "u32")])

    def new(self, setup):
        self.dets = setup.output_seq("dets", Detection, Header, max_len=1000)
        self.seen = setup.input_seq("seen", Detection, Header)

    def step(self, ctx):
        msg = self.dets.loan(len(found))     # header and len(found) elements, in shared memory
        msg.header.frame = ctx.cycle
        msg.items["x"] = found_x             # numpy, written in place
        self.dets.send(msg)
        for m in self.seen.drain():          # read in place, at each sample's own length
            print(m.header.frame, len(m.items), m.items["x"].max(initial=0))

``msg.items`` is a numpy structured array (a plain one for a primitive
element: ``"u8"`` for text) over the sample's own bytes: zero copy, valid
while the message lives; ``msg.header`` is a ``nerve.Message`` over the
header (None for a sequence without one). A loan past ``max_len`` is
refused (ValueError) before anything is loaned or sent.
"""

from __future__ import annotations

import json

import numpy as np

from . import _native


class Sequence:
    """A sequence payload type: ``header`` (a ``Payload``, or None) then
    any number of ``element``. Its ``type_name`` (``nerve::Seq<E, H>``) and
    ``fingerprint`` are those Rust gives ``Seq<E, H>``."""

    def __init__(self, element, header=None):
        from . import Payload, _field_schema

        if isinstance(element, Sequence) or isinstance(header, Sequence):
            raise ValueError("a sequence's header and element are fixed-size types, not sequences "
                             "(a sample ends in one sequence)")
        self.element = element if isinstance(element, Payload) else Payload(_field_schema(element))
        self.header = None if header is None else (header if isinstance(header, Payload) else Payload(_field_schema(header)))
        self.schema_json = _native.sequence_schema(
            self.element.schema_json, None if self.header is None else self.header.schema_json)
        self.schema = json.loads(self.schema_json)
        self.type_name = self.schema["type_name"]
        self.fingerprint = _native.fingerprint(self.schema_json)
        self.items_at, self.element_size, self.align = _native.sequence_shape(self.schema_json)
        if self.header is not None and self.header.size == 0:
            self.header = None

    def length_of(self, nbytes: int) -> int:
        """How many elements a sample of ``nbytes`` bytes holds."""
        rest = nbytes - self.items_at
        if rest < 0 or rest % self.element_size:
            raise ValueError(f"a {nbytes}-byte sample is not a {self.type_name} "
                             f"({self.items_at}-byte header and whole {self.element_size}-byte elements)")
        return rest // self.element_size

    def __repr__(self) -> str:
        return f"Sequence({self.type_name!r}, fingerprint {self.fingerprint:#018x})"


def sequence(element, header=None) -> Sequence:
    """The sequence type of ``element`` after ``header`` (each a primitive
    name, ``(type, n)``, a built-in type's name or a ``nerve.Payload``;
    ``header`` None for none), as Rust's ``Seq<element, header>``."""
    return Sequence(element, header)


def _views(buf, seq: Sequence, n: int):
    """The header Message (or None) and the items array over ``buf``."""
    from . import Message

    header = None
    if seq.header is not None:
        header = Message(np.frombuffer(buf, dtype=seq.header.dtype, count=1))
    if n == 0:
        items = np.empty(0, dtype=seq.element.dtype)
    else:
        items = np.frombuffer(buf, dtype=seq.element.dtype, count=n, offset=seq.items_at)
    return header, items


class SeqMessage:
    """One sequence sample, viewed in place: ``header`` (a ``nerve.Message``,
    or None), ``items`` (a numpy array of the sample's own length) and, for
    a received one, ``meta``. Like a fixed ``Message``, a received one keeps
    its sample in shared memory while it (or a view) lives, and a loaned one
    is spent by ``send``."""

    __slots__ = ("_header", "_items", "meta", "_loan", "type")

    def __init__(self, seq: Sequence, header, items, meta=None, loan=None):
        self.type = seq
        self._header = header
        self._items = items
        self.meta = meta
        self._loan = loan

    def _check(self):
        if self._items is None:
            raise RuntimeError(f"this {self.type.type_name} message was sent: its memory is the readers' now; "
                               "loan a new one (out.loan(n)), or keep msg.copy() before sending")

    @property
    def header(self):
        """The header as a ``nerve.Message`` (None for a sequence without one)."""
        self._check()
        return self._header

    @property
    def items(self) -> np.ndarray:
        """The elements: a numpy array of the sample's own length, a view of its memory."""
        self._check()
        return self._items

    def __len__(self) -> int:
        self._check()
        return len(self._items)

    @property
    def sent(self) -> bool:
        return self._items is None

    def copy(self) -> "SeqMessage":
        """A copy that holds no shared memory."""
        from . import Meta

        self._check()
        m = self.meta
        return SeqMessage(self.type, None if self._header is None else self._header.copy(), self._items.copy(),
                          None if m is None else Meta(m.sender, m.seq, m.stamp_ns))

    def to_dict(self) -> dict:
        """``{"header": {...}, "items": [...]}``, as ``nerve echo`` prints it."""
        self._check()
        items = self._items
        if items.dtype.names:
            listed = [{n: row[n].tolist() for n in items.dtype.names} for row in items]
        else:
            listed = items.tolist()
        return {"header": None if self._header is None else self._header.to_dict(), "items": listed}

    def _spend(self):
        """Drops this message's own views (before its loan is sent)."""
        if self._header is not None:
            object.__setattr__(self._header, "_a", None)
        self._header = None
        self._items = None

    def __repr__(self) -> str:
        if self._items is None:
            return f"SeqMessage({self.type.type_name}, sent)"
        return f"SeqMessage({self.type.type_name}, {len(self._items)} items)"


def received(r, seq: Sequence) -> SeqMessage:
    """A received sample (``_native.Received``) viewed as ``seq``."""
    from . import Meta

    header, items = _views(r, seq, seq.length_of(len(r)))
    return SeqMessage(seq, header, items, Meta(r.sender, r.seq, r.stamp_ns))


def decoded(data: bytes, seq: Sequence, meta=None) -> SeqMessage:
    """A copy of a sample's ``data`` viewed as ``seq`` (the test harness)."""
    buf = bytearray(data)
    header, items = _views(buf, seq, seq.length_of(len(buf)))
    return SeqMessage(seq, header, items, meta)


def encoded(seq: Sequence, message=None, header=None, items=None) -> bytes:
    """The bytes of a sample of ``seq``: a ``SeqMessage``, or ``header`` (a
    dict or Message) and ``items`` (anything numpy assigns to the element
    array: an array, a list of tuples, bytes for ``u8``)."""
    if message is not None:
        if not isinstance(message, SeqMessage):
            raise TypeError(f"a {seq.type_name} message is a SeqMessage, or header= and items=")
        header, items = message.header, message.items
    items = _items_array(seq, items)
    buf = bytearray(seq.items_at + len(items) * seq.element_size)
    h, slots = _views(buf, seq, len(items))
    _write_header(seq, h, header)
    slots[...] = items
    return bytes(buf)


def _items_array(seq: Sequence, items) -> np.ndarray:
    if items is None:
        return np.empty(0, dtype=seq.element.dtype)
    if isinstance(items, (bytes, bytearray, memoryview)):
        return np.frombuffer(items, dtype=seq.element.dtype)
    if isinstance(items, np.ndarray) and items.dtype == seq.element.dtype:
        return items
    if isinstance(items, np.ndarray) and items.dtype.names is None and seq.element.dtype.names is None:
        return items.astype(seq.element.dtype)
    return np.array([tuple(i[n] for n in seq.element.dtype.names) if isinstance(i, dict) else i for i in items],
                    dtype=seq.element.dtype)


def _write_header(seq: Sequence, h, header) -> None:
    from . import Message

    if header is None:
        return
    if h is None:
        raise ValueError(f"{seq.type_name} has no header")
    if isinstance(header, Message):
        h.array[...] = header.array
    elif isinstance(header, dict):
        for k, v in header.items():
            setattr(h, k, v)
    else:
        raise TypeError(f"a header is a dict of fields or a nerve.Message, not {type(header).__name__}")


class SeqInput:
    """An input port of a sequence type; the router connects it to output
    ports of the same header and element."""

    def __init__(self, native, seq: Sequence):
        self._n = native
        self.payload = seq

    def take(self):
        """The next waiting sample, in place, or None."""
        r = self._n.take()
        return None if r is None else received(r, self.payload)

    def drain(self):
        """Every waiting sample, in turn (take each before the next)."""
        while True:
            m = self.take()
            if m is None:
                return
            yield m

    def latest(self):
        """A copy of the newest waiting sample (the older ones are dropped), or None."""
        newest = None
        for m in self.drain():
            if newest is None or m.meta.stamp_ns >= newest.meta.stamp_ns:
                newest = m.copy()
        return newest

    @property
    def sources(self) -> int:
        return self._n.sources()


class SeqOutput:
    """An output port of a sequence type, taking at most ``max_len`` elements a sample."""

    def __init__(self, native, seq: Sequence):
        self._n = native
        self._port = native.port
        self.payload = seq

    @property
    def max_len(self) -> int:
        return self._n.max_len

    @property
    def service(self) -> str:
        return self._port.service

    def loan(self, n: int, zeroed: bool = True) -> SeqMessage:
        """A sample of ``n`` elements to write in place, then ``send``.
        ValueError past ``max_len``: nothing is loaned or sent."""
        loan = self._n.loan(int(n), zeroed)
        header, items = _views(loan, self.payload, int(n))
        return SeqMessage(self.payload, header, items, None, loan)

    def send(self, message=None, /, *, header=None, items=None) -> None:
        """Sends a loaned ``message``; or a new one of ``header`` (a dict
        or ``Message``) and ``items`` (written once, into shared memory);
        or ``bytes`` of a whole sample."""
        if isinstance(message, SeqMessage) and message._loan is not None and header is None and items is None:
            self._send_loaned(message)
            return
        if isinstance(message, (bytes, bytearray, memoryview)):
            self._port.send_bytes(message)
            return
        if message is not None:
            if not isinstance(message, SeqMessage):
                raise TypeError(f"send takes a SeqMessage, bytes, or header= and items=, not {type(message).__name__}")
            header, items = message.header, message.items
        items = _items_array(self.payload, items)
        m = self.loan(len(items))
        _write_header(self.payload, m._header, header)
        m._items[...] = items
        self._send_loaned(m)

    def _send_loaned(self, m: SeqMessage) -> None:
        """Sends a loaned message: drops its own views first (a loan is not
        sent while a view lives), and gives them back if the send fails."""
        header = m._header
        if m._items is None:
            raise RuntimeError("this message was sent already")
        m._spend()
        try:
            self._port.send(m._loan)
        except BaseException:
            if not m._loan.sent:
                with memoryview(m._loan) as v:
                    n = self.payload.length_of(v.nbytes)
                h, m._items = _views(m._loan, self.payload, n)
                if header is not None:
                    object.__setattr__(header, "_a", h.array)
                    m._header = header
            raise
