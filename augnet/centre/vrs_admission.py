"""When satellites the network newly corrects enter a VRS: at rare admission moments, all at once.

A rover without partial ambiguity resolution (RTKLIB 2.4.3 with its defaults: continuous AR, ratio 3) puts
every satellite's ambiguity into one integer search. A satellite the VRS adds (with a loss-of-lock flag, as it
must: its observations step by the network's correction) enters that search with a float ambiguity metres
wide; the ratio falls under 3 and the whole fix is lost for 6-50 s, at every satellite the network fixes
(issue 14: 46-82 % fixed after the first fix on network-70km's start). So a satellite the network newly
corrects waits; the waiting satellites enter together at an admission moment, and at that moment every
satellite of the VRS is flagged loss-of-lock: the rover restarts all its ambiguities at once, with all of
them equally well known, instead of dragging one metre-wide float through a fixed solution. Satellites the
network no longer corrects leave at once (one DD less costs a fixed rover little).

An admission moment is held when satellites wait and
  * the VRS is not a network VRS yet (single-base, or the start) but would be with them: as soon as the set is
    ready (below), without waiting for the interval;
  * it was a network VRS and without them no longer would be (the network lost satellites): at once;
  * the VRS changes its master station (every satellite restarts anyway): at once;
  * otherwise at least `interval_s` after the last moment, once ready;
where ready is: the corrected set has not changed for `settle_s` (the network has fixed what it was about to
fix), or `min_satellites` wait (entering: are corrected), or a satellite has waited `max_wait_s`.

`AdmissionPolicy.step(t, corrected)` is a pure state machine over time tags (no clock), one per VRS.
Decision 0160 has the measurements.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterable

from augnet.options import OptionError, setting


@dataclass(frozen=True)
class AdmissionConfig:
    admission: bool = setting(
        True, doc="admit newly corrected satellites only at admission moments, with every satellite of the VRS "
        "restarted (loss-of-lock) there; off: each enters as soon as it is corrected, flagged on its own",
        source="decision 0160")
    interval_s: float = setting(
        600.0, unit="s", doc="least time between two admission moments while the VRS stays a network VRS "
        "(a rover loses a few epochs of fix at each)", source="decision 0160")
    settle_s: float = setting(
        30.0, unit="s", doc="a moment is held once the corrected set has not changed for this long (the "
        "network has fixed the satellites it was about to fix)", source="decision 0160")
    min_satellites: int = setting(
        10, doc="... or as soon as this many satellites wait (entering network mode: as soon as this many are "
        "corrected)", source="decision 0160")
    max_wait_s: float = setting(
        120.0, unit="s", doc="... or once a satellite has waited this long (past the interval)",
        source="decision 0160")


def check_config(cfg: AdmissionConfig) -> None:
    """Raise OptionError naming the first setting out of range."""
    for name in ("interval_s", "settle_s", "max_wait_s"):
        if not getattr(cfg, name) >= 0.0:
            raise OptionError(f"{name}: {getattr(cfg, name)!r} is negative (seconds, >= 0)")
    if cfg.min_satellites < 1:
        raise OptionError(f"min_satellites: {cfg.min_satellites!r} is not a count of satellites (>= 1)")


@dataclass(frozen=True)
class Admission:
    """One epoch's decision."""

    carried: frozenset  # satellites the VRS epoch carries with network corrections (empty: single-base)
    restart: bool  # an admission moment: flag every carried satellite loss-of-lock
    waiting: frozenset  # corrected, not carried yet


class AdmissionPolicy:
    """The satellites a network VRS carries, epoch by epoch. `network_satellites(corrected)` is the rule of a
    network epoch (postprocess.network_satellites): the satellites an epoch may carry, empty when too few."""

    def __init__(self, config: AdmissionConfig | None = None,
                 network_satellites: Callable[[Iterable[str]], set] | None = None):
        self.config = config or AdmissionConfig()
        check_config(self.config)
        if network_satellites is None:
            from augnet.centre.postprocess import network_satellites
        self._rule = network_satellites
        self.carried: frozenset = frozenset()
        self.last_moment_t: float | None = None
        self._corrected: frozenset = frozenset()
        self._changed_t: float | None = None  # when the corrected set last changed
        self._waiting_since: dict[str, float] = {}
        self._free = False

    def restart(self) -> None:
        """The VRS restarts anyway at the next epoch (another master station: every satellite is flagged): make it
        a moment, so that the waiting satellites enter there instead of costing the rover a restart of their own."""
        self._free = True

    def step(self, t: float, corrected: Iterable[str]) -> Admission:
        """The decision for the epoch at `t` [s] whose network-corrected satellites are `corrected`."""
        cfg = self.config
        corrected = frozenset(map(str, corrected))
        if corrected != self._corrected or self._changed_t is None:
            self._corrected, self._changed_t = corrected, t
        eligible = frozenset(self._rule(corrected))
        free, self._free = self._free, False
        if not cfg.admission:
            self.carried = eligible
            return Admission(eligible, False, frozenset())
        kept = frozenset(self._rule(self.carried & eligible))  # the network's losses leave at once
        waiting = eligible - kept
        self._waiting_since = {s: self._waiting_since.get(s, t) for s in waiting}
        if waiting:
            entering = not kept  # without the waiting satellites this is no network epoch
            falling = entering and bool(self.carried)  # ... and it was one: the rover restarts anyway
            due = entering or self.last_moment_t is None or t - self.last_moment_t >= cfg.interval_s
            ready = (t - self._changed_t >= cfg.settle_s
                     or len(eligible if entering else waiting) >= cfg.min_satellites
                     or t - min(self._waiting_since.values()) >= cfg.max_wait_s)
            if free or falling or (due and ready):
                self.carried, self.last_moment_t, self._waiting_since = eligible, t, {}
                return Admission(eligible, True, frozenset())
        self.carried = kept
        return Admission(kept, False, waiting)
