"""The per-channel timestamp LFSRs: T(0) = SINIT, T(n) = LFSR(T(n-1)), one LFSR cycle per main cycle.

T is a function of the TC field, T(TC) = M^TC SINIT, which is how the check words bind a TC. Both
polynomials are primitive: M has order 2^32 - 1, one less than the u32 TC's modulus, so a sender starts
again from SINIT when its TC wraps to 0 (rssp1.endpoint).

Each channel's LFSR is a 32-bit Galois register shifting left; when the bit shifted out is 1 the
polynomial is XORed in. One main cycle clocks it 32 times (rssp1.md "Codes"). Polynomials: channel 1
0x0FC22F87, channel 2 0xC3E887E1.

Clocking is linear over GF(2), so one main cycle is a 32x32 bit matrix M. We keep it as four 256-entry
tables (one per input byte), making a cycle four lookups, and get M**n by squaring, so the timestamp of
any TC (a capture starting at TC 7705, a receiver bridging a gap) costs O(log n) table compositions
instead of 32*n shifts.
"""

from __future__ import annotations

from dataclasses import dataclass

MASK32 = 0xFFFFFFFF
TIMESTAMP_CH1_POLY = 0x0FC22F87  # rssp1.md "Codes", channel 1
TIMESTAMP_CH2_POLY = 0xC3E887E1  # rssp1.md "Codes", channel 2
LFSR_STEPS_PER_CYCLE = 32  # rssp1.md: 32 shifts per main cycle


def lfsr_shift(value: int, poly: int, steps: int = LFSR_STEPS_PER_CYCLE) -> int:
    """Reference bit-serial Galois LFSR: `steps` left shifts of `value` with feedback `poly`."""
    for _ in range(steps):
        carry = value & 0x80000000
        value = (value << 1) & MASK32
        if carry:
            value ^= poly
    return value


@dataclass(frozen=True)
class LinearMap32:
    """A GF(2)-linear map on 32-bit words, stored as four byte-indexed tables."""

    tables: tuple[tuple[int, ...], tuple[int, ...], tuple[int, ...], tuple[int, ...]]

    @classmethod
    def from_function(cls, f) -> "LinearMap32":
        basis = [f(1 << i) for i in range(32)]
        tables = []
        for byte_index in range(4):
            column = basis[8 * byte_index : 8 * byte_index + 8]
            table = [0] * 256
            for x in range(1, 256):
                low = x & -x
                table[x] = table[x ^ low] ^ column[low.bit_length() - 1]
            tables.append(tuple(table))
        return cls(tuple(tables))  # type: ignore[arg-type]

    def __call__(self, x: int) -> int:
        t0, t1, t2, t3 = self.tables
        return t0[x & 0xFF] ^ t1[(x >> 8) & 0xFF] ^ t2[(x >> 16) & 0xFF] ^ t3[x >> 24]

    def then(self, other: "LinearMap32") -> "LinearMap32":
        """The map x -> other(self(x))."""
        return LinearMap32.from_function(lambda x: other(self(x)))

    def rows(self) -> list[int]:
        """The images of the 32 basis vectors (column i of the matrix = image of bit i)."""
        return [self(1 << i) for i in range(32)]


IDENTITY32 = LinearMap32.from_function(lambda x: x)


class TimestampLfsr:
    """One channel's timestamp generator: `step(T)` is one main cycle, `advance(T, n)` is n cycles."""

    # Jumps up to this many cycles are done by repeated single steps (4 lookups each); longer ones by
    # the powers of M kept in _powers. Receivers bridge gaps smaller than deltaTime, so this is rare.
    _DIRECT_STEP_LIMIT = 8

    def __init__(self, poly: int) -> None:
        self.poly = poly
        self.cycle = LinearMap32.from_function(lambda x: lfsr_shift(x, poly))
        self._powers: list[LinearMap32] = [self.cycle]  # M**(2**k)
        # step(T) = one main cycle: the map's four lookups in a plain function (no method dispatch,
        # no attribute lookups), as every frame sent and every frame verified takes one.
        self.step = _four_lookups(self.cycle.tables)

    def _power(self, k: int) -> LinearMap32:
        while len(self._powers) <= k:
            last = self._powers[-1]
            self._powers.append(last.then(last))
        return self._powers[k]

    def advance(self, value: int, cycles: int) -> int:
        """T(n + cycles) given T(n)."""
        if cycles < 0:
            raise ValueError("the timestamp LFSR only runs forward")
        if cycles == 1:  # the common case: consecutive frames
            return self.step(value)
        if cycles <= self._DIRECT_STEP_LIMIT:
            step = self.cycle
            for _ in range(cycles):
                value = step(value)
            return value
        k = 0
        while cycles:
            if cycles & 1:
                value = self._power(k)(value)
            cycles >>= 1
            k += 1
        return value

    def power_map(self, cycles: int) -> LinearMap32:
        """M**cycles as a linear map (for solving equations in rssp1.sid_recovery)."""
        result = IDENTITY32
        k = 0
        while cycles:
            if cycles & 1:
                result = result.then(self._power(k))
            cycles >>= 1
            k += 1
        return result


def _four_lookups(tables):
    t0, t1, t2, t3 = tables

    def step(value: int) -> int:
        """One main cycle of this channel's timestamp LFSR."""
        return t0[value & 0xFF] ^ t1[(value >> 8) & 0xFF] ^ t2[(value >> 16) & 0xFF] ^ t3[value >> 24]

    return step


TIMESTAMP_CH1 = TimestampLfsr(TIMESTAMP_CH1_POLY)
TIMESTAMP_CH2 = TimestampLfsr(TIMESTAMP_CH2_POLY)
TIMESTAMP_LFSRS = (TIMESTAMP_CH1, TIMESTAMP_CH2)


def timestamp_at(sinit: tuple[int, int], tc: int) -> tuple[int, int]:
    """Both channels' T(tc) for a sender whose timestamps start at T(0) = sinit."""
    return TIMESTAMP_CH1.advance(sinit[0], tc), TIMESTAMP_CH2.advance(sinit[1], tc)


def _pair_stepper():
    a0, a1, a2, a3 = TIMESTAMP_CH1.cycle.tables
    b0, b1, b2, b3 = TIMESTAMP_CH2.cycle.tables

    def step_pair(t: tuple[int, int]) -> tuple[int, int]:
        """Both channels' T(n + 1) from T(n): what every sent or verified RSD takes, in one call."""
        x, y = t
        return (
            a0[x & 0xFF] ^ a1[(x >> 8) & 0xFF] ^ a2[(x >> 16) & 0xFF] ^ a3[x >> 24],
            b0[y & 0xFF] ^ b1[(y >> 8) & 0xFF] ^ b2[(y >> 16) & 0xFF] ^ b3[y >> 24],
        )

    return step_pair


step_pair = _pair_stepper()


def advance_pair(t: tuple[int, int], cycles: int) -> tuple[int, int]:
    """Both channels' T(n + cycles) from T(n)."""
    if cycles == 1:
        return step_pair(t)
    return TIMESTAMP_CH1.advance(t[0], cycles), TIMESTAMP_CH2.advance(t[1], cycles)
