"""A baseline's fixed double-difference integers, kept against each system's reference satellite.

SD ambiguities carry the SD receiver phase bias, common to one system's satellites, so only their DD are integers:
N1 and N2 per satellite, and the wide lane N1 - N2, held on its own while the satellite's narrow lane is open.
When a system's reference changes the DD are re-referenced: N(s, new) = N(s, old) - N(new, old).
(An immutable set of DD integers by satellite pair, as a fix reports it, is `augnet.gnss.ambiguity.FixedIntegers`.)
"""

from __future__ import annotations

from dataclasses import dataclass, field

# The tables, as indices: the two frequencies' N1 and N2, then the wide lane N1 - N2
N1, N2, WIDE_LANE = 0, 1, 2
FREQUENCY_TABLES = (N1, N2)
ALL_TABLES = (N1, N2, WIDE_LANE)


@dataclass
class BaselineIntegers:
    """satellite -> DD integer [cycles] against its system's reference, per table."""

    n1: dict[str, int] = field(default_factory=dict)
    n2: dict[str, int] = field(default_factory=dict)
    wide_lane: dict[str, int] = field(default_factory=dict)

    def table(self, kind: int) -> dict[str, int]:
        return (self.n1, self.n2, self.wide_lane)[kind]

    def tables(self) -> tuple[dict[str, int], dict[str, int], dict[str, int]]:
        return self.n1, self.n2, self.wide_lane

    def both(self, sat: str) -> bool:
        """N1 and N2 known: the satellite's DD integers are fixed."""
        return sat in self.n1 and sat in self.n2

    def any_frequency(self, sat: str) -> bool:
        return sat in self.n1 or sat in self.n2

    def frequency_count(self) -> int:
        """DD ambiguities fixed on either frequency (wide lanes held on their own not counted)."""
        return len(self.n1) + len(self.n2)

    def forget(self, sat: str) -> None:
        for table in self.tables():
            table.pop(sat, None)

    def rereference(self, system: str, old: str, new: str) -> None:
        """Carry one system's DD integers from reference `old` over to `new`; a table that has no integer for
        `new` loses the system's."""
        for table in self.tables():
            offset = table.get(new)  # N(new, old)
            sats = [s for s in table if s[0] == system]
            if offset is None:
                for s in sats:
                    del table[s]
                continue
            for s in sats:
                table[s] = table[s] - offset
            table.pop(new, None)
            table[old] = -offset
