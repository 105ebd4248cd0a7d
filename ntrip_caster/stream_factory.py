"""The interface between the caster and whoever synthesises per-client streams (VRS).

The control centre (augnet.centre, a later issue) implements `StreamFactory`; the caster never
imports it, it loads it by name from the configuration (`factory = "module:attribute"`) or takes
an instance from the embedding program.

Life of one VRS client:
  1. the client connects to a `vrs` mountpoint; the caster answers OK and keeps it connected
  2. its first usable GGA arrives -> `handle = factory.open(client_id, mount, fix, sink)`
  3. whenever the client has moved enough (reposition policy, `reposition.py`) ->
     `handle.update_position(fix)`
  4. the client leaves or is dropped -> `handle.close()`

`open` and `update_position` may raise `StreamRefused` (a position outside the service area, say): the
caster writes its `data` (a message the client can read, e.g. an RTCM 1029 text), closes the connection
and counts it as `refused` on the mountpoint (a refused handle is not closed: the factory let it go). Any other exception is a factory bug (`factory_error`).

`sink(data)` queues whole RTCM 3 frames (ideally one epoch per call) for that client. It must be
called on the caster's event loop thread; a factory working in another thread uses
`loop.call_soon_threadsafe(sink, data)`. After `close()` the sink ignores anything it is given.
"""

from __future__ import annotations

import importlib
from typing import Callable, Protocol, runtime_checkable

from augwire.errors import StreamRefused

from .gga import GgaFix

Sink = Callable[[bytes], None]


@runtime_checkable
class StreamHandle(Protocol):
    def update_position(self, fix: GgaFix) -> None: ...

    def close(self) -> None: ...


@runtime_checkable
class StreamFactory(Protocol):
    def open(self, client_id: str, mount: str, fix: GgaFix, sink: Sink) -> StreamHandle: ...


def load_factory(spec: str) -> StreamFactory:
    """`package.module:attribute` -> the factory (an instance, or a class/callable returning one)."""
    module_name, sep, attr = spec.partition(":")
    if not sep or not module_name or not attr:
        raise ValueError(f"factory {spec!r}: expected 'package.module:attribute'")
    obj = getattr(importlib.import_module(module_name), attr)
    if not isinstance(obj, StreamFactory) and callable(obj):
        obj = obj()
    if not isinstance(obj, StreamFactory):
        raise ValueError(f"factory {spec!r} has no open(client_id, mount, fix, sink) method")
    return obj


__all__ = ["Sink", "StreamFactory", "StreamHandle", "StreamRefused", "load_factory"]
