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
  * the VRS changes its master station (every satellite restarts anyway): at once; not when the VRS was handed
    over to the new master (vrs_handover.py, decision 0223: its satellites keep their locks);
  * otherwise at least `interval_s` after the last moment, once ready;
where ready is: the corrected set has not changed for `settle_s` (the network has fixed what it was about to
fix), or `min_satellites` wait (entering: are corrected), or a satellite has waited `max_wait_s`.

`AdmissionPolicy.step(t, corrected)` is a pure state machine over time tags (no clock), one per VRS: what
`augnet vrs` runs. `AdmissionBatch` makes the same decisions for many VRS at once (sessions x satellites as
arrays): what the live stream (`engine.CentreEngine`, `augnet up`) runs for its trains, each session with its own
state. Decision 0160 has the measurements, 0190 the live stream.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterable

import numpy as np

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


def flag(name: str) -> str:
    """The command-line flag of a setting: `--admission`, `--admission-interval-s`, ... (`augnet vrs`, `augnet up`)."""
    return "--admission" + ("" if name == "admission" else "-" + name.replace("_", "-"))


def config_from_flags(values: dict) -> AdmissionConfig:
    """The settings from flag values {setting: text, None for its default}; OptionError names the flag and value."""
    from augnet.options import with_assignments

    cfg = AdmissionConfig()
    for name, value in values.items():
        if value is None:
            continue
        try:
            cfg = with_assignments(cfg, [f"{name}={value}"])
            check_config(cfg)
        except OptionError as exc:
            raise OptionError(f"{flag(name)} {value}: {exc}") from None
    return cfg


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


def fixed_somewhere(ne) -> set[str]:
    """Satellites of a network epoch with a DD residual at some station besides the network master (row 0).
    Only these count as corrected: interpolation.interpolate() returns the master's zero when only the master
    "has" a satellite, and synthesize() then flags it corrected though no baseline fixed it (seen with
    `--master` = the point's nearest station: all satellites "corrected" from the first epoch)."""
    if len(ne.stations) < 2 or not len(ne.sats):
        return set()
    return set(map(str, ne.sats[np.isfinite(ne.dd_iono_m[1:]).any(axis=0)]))


def _capacity(have: int, need: int, least: int) -> int:
    """An array axis's new length: unchanged while it holds `need`, else doubled (amortised growth)."""
    return have if need <= have else max(need, 2 * have, least)


class AdmissionBatch:
    """`AdmissionPolicy` for many VRS at once, keyed by session: the same decisions (tests compare them), each
    session with its own state, computed as arrays over sessions x satellites. The rule of a network epoch is
    postprocess.network_satellites's, counted per system over the arrays."""

    def __init__(self, config: AdmissionConfig | None = None):
        from augnet.centre.postprocess import MIN_NETWORK_DD, MIN_SYSTEM_SATELLITES

        self.config = config or AdmissionConfig()
        check_config(self.config)
        self._min_system, self._min_dd = MIN_SYSTEM_SATELLITES, MIN_NETWORK_DD
        self._rows: dict = {}  # session key -> row
        self._free_rows: list[int] = []
        self._cols: dict[str, int] = {}  # satellite -> column
        self._systems: dict[str, int] = {}  # system letter -> index
        self._col_system = np.zeros(0, int)
        self._masters: dict = {}  # session key -> master station of its last step
        self._alloc(0, 0)

    def _alloc(self, rows: int, cols: int) -> None:
        self.carried = np.zeros((rows, cols), bool)
        self._corrected = np.zeros((rows, cols), bool)
        self._waiting_since = np.full((rows, cols), np.nan)
        self._changed_t = np.full(rows, np.nan)  # NaN: never stepped
        self._last_moment_t = np.full(rows, np.nan)  # NaN: no moment yet
        self._free = np.zeros(rows, bool)

    def _grow(self, rows: int, cols: int) -> None:
        r0, k0 = self.carried.shape
        if rows <= r0 and cols <= k0:
            return
        old = (self.carried, self._corrected, self._waiting_since, self._changed_t, self._last_moment_t, self._free)
        self._alloc(_capacity(r0, rows, 16), _capacity(k0, cols, 64))
        for new, a in zip((self.carried, self._corrected, self._waiting_since, self._changed_t,
                           self._last_moment_t, self._free), old):
            new[tuple(slice(0, n) for n in a.shape)] = a

    def _row(self, key) -> int:
        r = self._rows.get(key)
        if r is None:
            r = self._free_rows.pop() if self._free_rows else len(self._rows)
            self._rows[key] = r
            self._grow(r + 1, len(self._cols))
            self.carried[r] = self._corrected[r] = False
            self._waiting_since[r] = self._changed_t[r] = self._last_moment_t[r] = np.nan
            # a session's first epoch is a moment: its rover has no lock to lose yet (a train joining a network
            # in service takes every corrected satellite at once instead of an empty VRS for `settle_s`)
            self._free[r] = True
        return r

    def _col(self, sat: str) -> int:
        k = self._cols.get(sat)
        if k is None:
            k = self._cols[sat] = len(self._cols)
            system = self._systems.setdefault(sat[0], len(self._systems))
            self._col_system = np.append(self._col_system, system)
        return k

    def remove(self, key) -> None:
        """A session closed: its row is free for the next one (which starts afresh)."""
        r = self._rows.pop(key, None)
        self._masters.pop(key, None)
        if r is not None:
            self._free_rows.append(r)

    def restart(self, keys) -> None:
        """As AdmissionPolicy.restart, for these sessions."""
        self._free[[self._row(k) for k in keys]] = True

    def _rule(self, corrected: np.ndarray) -> np.ndarray:
        """network_satellites over rows: each system with enough satellites, when they give enough DDs."""
        onehot = self._col_system[:corrected.shape[1], None] == np.arange(max(len(self._systems), 1))[None, :]
        counts = corrected.astype(np.int64) @ onehot  # (rows, systems)
        systems = counts >= self._min_system
        enough = ((counts - 1) * systems).sum(axis=1) >= self._min_dd
        return corrected & systems[:, self._col_system[:corrected.shape[1]]] & enough[:, None]

    def step(self, t: float, keys: list, sats, corrected: np.ndarray, masters: list | None = None,
             handed_over: np.ndarray | None = None):
        """One epoch at `t` [s] for the sessions `keys`: `corrected` (sessions x `sats`) their network-corrected
        satellites; `masters` (one per session) their master stations (a change is a moment for the waiting,
        unless the session's VRS was handed over to the new master, `handed_over`: its locks continue).
        Returns (carried (sessions x sats) bool, moment (sessions,) bool)."""
        cfg = self.config
        sat_cols = np.array([self._col(str(s)) for s in sats], dtype=int)
        if masters is not None:
            kept = [False] * len(keys) if handed_over is None else [bool(h) for h in handed_over]
            changed_master = [k for k, m, h in zip(keys, masters, kept) if self._masters.get(k, m) != m and not h]
            if changed_master:
                self.restart(changed_master)
            self._masters.update(zip(keys, masters))
        rows = np.array([self._row(k) for k in keys], dtype=int)
        self._grow(len(self._rows), len(self._cols))
        K = len(self._cols)
        corr = np.zeros((len(rows), K), bool)
        corr[:, sat_cols] = np.asarray(corrected, bool)
        changed = np.isnan(self._changed_t[rows]) | (corr != self._corrected[rows, :K]).any(axis=1)
        changed_t = np.where(changed, t, self._changed_t[rows])
        self._changed_t[rows] = changed_t
        self._corrected[rows, :K] = corr
        eligible = self._rule(corr)
        free = self._free[rows]
        self._free[rows] = False
        if not cfg.admission:
            self.carried[rows, :K] = eligible
            return eligible[:, sat_cols], np.zeros(len(rows), bool)
        before = self.carried[rows, :K]
        kept = self._rule(before & eligible)  # the network's losses leave at once
        waiting = eligible & ~kept
        since = self._waiting_since[rows, :K]
        since = np.where(waiting, np.where(np.isnan(since), t, since), np.nan)
        entering = ~kept.any(axis=1)  # without the waiting satellites this is no network epoch
        falling = entering & before.any(axis=1)  # ... and it was one: the rover restarts anyway
        last = self._last_moment_t[rows]
        with np.errstate(invalid="ignore"):
            due = entering | np.isnan(last) | (t - last >= cfg.interval_s)
        oldest = np.where(waiting, since, np.inf).min(axis=1, initial=np.inf)
        ready = ((t - changed_t >= cfg.settle_s)
                 | (np.where(entering, eligible.sum(axis=1), waiting.sum(axis=1)) >= cfg.min_satellites)
                 | (t - oldest >= cfg.max_wait_s))
        moment = waiting.any(axis=1) & (free | falling | (due & ready))
        carried = np.where(moment[:, None], eligible, kept)
        self.carried[rows, :K] = carried
        self._last_moment_t[rows] = np.where(moment, t, last)
        self._waiting_since[rows, :K] = np.where(moment[:, None], np.nan, since)
        return carried[:, sat_cols], moment
