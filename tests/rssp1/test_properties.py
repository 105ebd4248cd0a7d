"""Property: whatever a faulty bearer does (drop, duplicate, hold and release reversed, flip a bit
with or without recomputing CRC16, flip the same bit of every frame and recompute CRC16, replay), the
receiver delivers only data the sender sent, at the TC it was sent with, in strictly increasing TC
order, each at most once; and once the bearer is clean again the link is back within the configured
bound."""

from __future__ import annotations

import os
import struct

from hypothesis import example, given, settings
from hypothesis import strategies as st

from rssp1.config import LinkTiming
from rssp1.crc import crc16
from rssp1.endpoint import DataReceived

from .linkpair import LinkPair

TIMING = LinkTiming(cycle_s=0.25, delta_time=3, life_time=4, delay_time=3)
# More examples for a deeper run: RSSP1_PROPERTY_EXAMPLES=20000 pytest tests/rssp1/test_properties.py
MAX_EXAMPLES = int(os.environ.get("RSSP1_PROPERTY_EXAMPLES", "120"))
ACTIONS = st.sampled_from(
    ["deliver", "drop", "duplicate", "hold", "flip", "flip_fix_crc", "stuck_fix_crc", "release", "replay_old"]
)
# stuck_fix_crc: a faulty bearer element that flips the same bit of every frame it passes and then
# recomputes CRC16; the bit is drawn once per example among the first 20 bytes (in every frame type).
# On the TC field it shifts TC_R and the TCs after it alike: the relabelling fault of the @example.


@settings(max_examples=MAX_EXAMPLES, deadline=None)
@given(st.lists(st.tuples(ACTIONS, ACTIONS, st.integers(0, 10_000)), min_size=5, max_size=60), st.integers(0, 159))
# Found by Hypothesis: bit 50 is bit 2 of the TC field. The SSR's TC_R goes 1005 -> 1001 and the next
# RSD's TC 1006 -> 1002, CRC16 recomputed both times; before TC_R was bound to its own timestamp the
# receiver delivered b"cycle 6" labelled TC 1002 (see Endpoint._receive_ssr).
@example(plan=[("deliver", "deliver", 0), ("drop", "deliver", 0), ("deliver", "deliver", 0), ("deliver", "deliver", 0),
               ("deliver", "deliver", 0), ("flip_fix_crc", "deliver", 50), ("flip_fix_crc", "deliver", 50)], stuck_bit=0)
def test_faulty_bearer_never_breaks_the_delivery_invariants(plan, stuck_bit):
    pair = LinkPair(TIMING)
    sent: dict[int, bytes] = {}
    history: list[bytes] = []
    held: list[bytes] = []
    current = {"action": "deliver", "seed": 0}

    def bearer(direction_action):
        def hook(cycle, frame):
            action, seed = current[direction_action], current["seed"]
            history.append(frame)
            if action == "drop":
                return []
            if action == "duplicate":
                return [frame, frame]
            if action == "hold":
                held.append(frame)
                return []
            if action == "release":
                out = held[::-1] + [frame]  # held frames come out late and reversed
                held.clear()
                return out
            if action in ("flip", "flip_fix_crc", "stuck_fix_crc"):
                bit = stuck_bit if action == "stuck_fix_crc" else seed % (len(frame) * 8)
                bad = bytearray(frame)
                bad[bit // 8] ^= 1 << (bit % 8)
                if action == "stuck_fix_crc":
                    bad[-2:] = struct.pack("<H", crc16(bytes(bad[:-2])))
                    return [bytes(bad)]
                if action == "flip_fix_crc":
                    bad[-2:] = struct.pack("<H", crc16(bytes(bad[:-2])))
                return [bytes(bad), frame] if seed % 2 else [bytes(bad)]
            if action == "replay_old":
                return [history[seed % len(history)], frame]
            return [frame]
        return hook

    pair.to_b = bearer("to_b")
    pair.to_a = bearer("to_a")
    delivered: list[DataReceived] = []
    for n, (to_b, to_a, seed) in enumerate(plan):
        current.update(to_b=to_b, to_a=to_a, seed=seed)
        payload = b"cycle %d" % n
        sent[pair.a.tc] = payload
        delivered += [e for e in pair.step(payload) if isinstance(e, DataReceived)]
    tcs = [e.tc for e in delivered]
    assert tcs == sorted(set(tcs)), "delivered out of order or twice"
    for e in delivered:
        assert sent.get(e.tc) == e.data, "delivered data the sender never sent at that TC"
    # clean bearer: back up within the bound (plus the cycles a held frame may still be in flight)
    current.update(to_b="deliver", to_a="deliver")
    for extra in range(TIMING.resync_bound_cycles + 2):
        payload = b"clean %d" % extra
        sent[pair.a.tc] = payload
        for e in pair.step(payload):
            if isinstance(e, DataReceived):
                assert sent.get(e.tc) == e.data
        if pair.a.is_up and pair.b.is_up:
            break
    assert pair.a.is_up and pair.b.is_up, (pair.b.stats, pair.a.stats)
