"""Confirmation of integer decisions: a DD ambiguity is fixed once the same integer has come out on several
consecutive epochs (fewer when the fixed block's success rate is very high).

A single epoch's LAMBDA decision can be wrong where near-equivalent integer pairs are close; a wrong pair rarely
wins several epochs running while the float solution keeps moving. (The onboard RTK confirms whole decisions
instead: `augnet.gnss.fix_confirmation`.)
"""

from __future__ import annotations


class IntegerStreaks:
    """Per satellite and integer table (`baseline_integers.N1`, `N2`, `WIDE_LANE`): the integer pinned on the
    latest epochs and how many consecutive epochs pinned it."""

    def __init__(self, epochs: int, epochs_sure: int):
        self.epochs = epochs
        self.epochs_sure = epochs_sure
        self._pending: dict[tuple[str, int], tuple[int, int]] = {}  # (sat, table) -> (integer, streak)

    def observe(self, sat: str, table: int, value: int, sure: bool) -> bool:
        """This epoch pinned `value`; True once it has been pinned on enough consecutive epochs."""
        prev = self._pending.get((sat, table))
        streak = prev[1] + 1 if prev is not None and prev[0] == value else 1
        self._pending[(sat, table)] = (value, streak)
        return streak >= (self.epochs_sure if sure else self.epochs)

    def clear(self, sat: str, table: int) -> None:
        """This epoch pinned nothing: the streak starts again."""
        self._pending.pop((sat, table), None)

    def forget(self, sat: str) -> None:
        for key in [k for k in self._pending if k[0] == sat]:
            del self._pending[key]

    def forget_system(self, system: str) -> None:
        for key in [k for k in self._pending if k[0][0] == system]:
            del self._pending[key]

    def forget_all(self) -> None:
        self._pending.clear()

