"""The correction bus: one small interface, an in-process implementation and a NATS JetStream one.

Publishers (the centre) put bytes on a subject; subscribers (caster nodes, the console, the RSSP-I link)
receive every message published after they subscribed, in order. Subjects are dot-separated tokens with NATS
wildcards (`*` one token, `>` the rest), so the same names work on both implementations.

    bus = InProcessBus()                      # or: await JetStreamBus.connect("nats://127.0.0.1:4222")
    sub = await bus.subscribe("augnet.corrections.>")
    await bus.publish("augnet.corrections.line1", payload)
    msg = await sub.next(timeout=1.0)
"""

from augnet.bus.core import Bus, BusError, Message, Subscription, subject_matches, validate_subject
from augnet.bus.inprocess import InProcessBus

__all__ = ["Bus", "BusError", "Message", "Subscription", "InProcessBus", "subject_matches",
           "validate_subject", "open_bus"]


async def open_bus(url: str | None) -> Bus:
    """The bus for a URL: None or "inprocess://" gives the in-process bus, "nats://..." JetStream."""
    if not url or url.startswith("inprocess:"):
        return InProcessBus()
    if url.startswith(("nats://", "tls://")):
        from augnet.bus.jetstream import JetStreamBus

        return await JetStreamBus.connect(url)
    raise BusError(f"bus URL {url!r}: expected inprocess:// or nats://HOST:PORT")
