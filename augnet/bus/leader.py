"""Leader lease for a region's active/standby centres in a JetStream key-value bucket (issue 17).

The bucket's max age is the lease TTL: a holder that stops renewing loses the key, and a candidate then
wins it with `create`. Renewal is `update` with the expected revision, so a holder that was paused and
resumed fails (wrong last sequence) and steps down. The KV revision is the lease revision models carry
(augnet.cluster.envelope) so edges fence a deposed leader.
"""
from __future__ import annotations

from nats.js.errors import KeyValueError

RENEW_FRACTION = 1 / 3  # renew every TTL/3 (issue 17 brief)


class Lease:
    def __init__(self, kv, region: str, holder: str):
        self.kv, self.key, self.holder = kv, f"leader.{region}", holder
        self.revision: int | None = None

    @property
    def held(self) -> bool:
        return self.revision is not None

    async def try_acquire(self) -> bool:
        """Win the lease if nobody holds it (the key is absent or expired)."""
        if self.held:
            return await self.renew()
        try:
            self.revision = await self.kv.create(self.key, self.holder.encode())
        except KeyValueError:
            self.revision = None
        return self.held

    async def renew(self) -> bool:
        """Extend the lease; on any failure (another holder, expiry, bus error) step down."""
        if not self.held:
            return False
        try:
            self.revision = await self.kv.update(self.key, self.holder.encode(), last=self.revision)
        except Exception:  # noqa: BLE001 - any failed renewal means this holder must stop publishing
            self.revision = None
        return self.held
