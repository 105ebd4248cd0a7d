"""A lease candidate process for the cluster tests: prints `HELD <revision> <monotonic>` on each win/renewal."""
import asyncio
import sys
import time

import nats

from augnet.bus.leader import RENEW_FRACTION, Lease


async def main(urls: str, name: str, ttl_s: float) -> None:
    nc = await nats.connect(servers=urls.split(","), connect_timeout=5, max_reconnect_attempts=-1)
    js = nc.jetstream()
    kv = await js.key_value("leases")
    lease = Lease(kv, "north", name)
    while True:
        if await lease.try_acquire():
            print(f"HELD {lease.revision} {time.monotonic():.3f}", flush=True)
        await asyncio.sleep(ttl_s * RENEW_FRACTION)


if __name__ == "__main__":
    asyncio.run(main(sys.argv[1], sys.argv[2], float(sys.argv[3])))
