"""Two RSSP-I endpoints joined over loopback UDP and run as tasks (the RBC and ATP simulators in `augnet up`)."""

from __future__ import annotations

import asyncio

from rssp1.transport import UdpLink


async def open_pair(near, far, cycle_s: float, host: str = "127.0.0.1") -> tuple[list, list]:
    """`near` and `far` linked to each other on free loopback ports: (links [near, far], their run tasks)."""
    far_link = await UdpLink.open(far, cycle_s, (host, 0), (host, 9))  # port 9 (discard) until near is bound
    near_link = await UdpLink.open(near, cycle_s, (host, 0), far_link.local_address)
    far_link.remote = near_link.local_address
    links = [near_link, far_link]
    return links, [asyncio.ensure_future(link.run()) for link in links]


async def close(links: list, tasks: list) -> None:
    """Close every link (a close may be a coroutine), cancel and reap their tasks."""
    for link in links:
        r = link.close()
        if asyncio.iscoroutine(r):
            await r
    for t in tasks:
        t.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)
