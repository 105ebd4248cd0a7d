"""An hour of `network-70km` (quiet ionosphere; four stations on a square of 50 km sides, the baselines along its
sides): no wrong fix against the simulator's truth, and how long fixing takes.

Time to fix, two definitions (issue 5 asks "every baseline's ambiguities fixed within a median 60 s"):

* per baseline, from a cold start: seconds from a solver's first epoch until the baseline has fixed its first
  satellite, half, and 80 % of the satellites it may fix (DD ambiguities on both frequencies of the satellites
  above `fix_min_elevation_deg` at both stations, references excluded). Three cold starts on the same data:
  the hour's solver at 0 s, and two more solvers started at 20 and 40 minutes, run for 5 minutes each;
* per new satellite arc after the solver started, a satellite rising, or back after a receiver event (a gap, a
  slip or an unflagged phase reset the centre detects; decision 0272): seconds from the first epoch the satellite
  may be fixed (above the fixing mask at both stations) until it is fixed. Arcs that end, or outlast the hour,
  before a fix are counted as censored; arcs already there at a cold start belong to the first definition.

Every fixed DD ambiguity of every solver, every epoch, is checked against the truth.
"""

from __future__ import annotations

import numpy as np
import pytest

from augnet.centre.network import NetworkSolver
from augnet.gnss.ionosphere import IONO_K_M3_S2
from stations.network_truth import true_dd_integers
from stations.scenario import load_scenario
from stations.world import World
from tests.centre.simdata import station_epochs
from tests.conftest import LONG_RUN_TIMEOUT_S

pytestmark = [pytest.mark.slow, pytest.mark.timeout(LONG_RUN_TIMEOUT_S)]

HOUR_S = 3600
COLD_STARTS_S = (1200, 2400)  # extra solvers, besides the hour's own start at 0 s
COLD_RUN_S = 300
SHARES = (0.5, 0.8)  # fixed share of the fixable satellites for the cold-start figures


MODEL_CHECK_EVERY_S = 10
LOW_DEG = 20.0  # "low": the satellites the model is for, 15-20 degrees at the lower station
# An arc that starts within this of the same satellite's last epoch, or at a slip, after an arc that reached the
# fixing mask, is the satellite back after a receiver event (gap, slip, phase reset: decision 0272), not a rising
# one: the statistics call a gap of up to 15 min a gap, a longer one a new pass (PASS_GAP_MAX_S,
# stations/observation_statistics.py).
BACK_MAX_GAP_S = 900


def _rms(v) -> float:
    return float(np.sqrt(np.mean(np.square(v))))


def _model_against_truth(model, solver, res, stec_tecu, ids, col) -> list[tuple]:
    """The network's ionosphere model's prediction for a baseline's satellites not fixed yet (above the fixing
    mask, references excluded) beside the simulator's DD ionosphere on f1."""
    mean, var = model.predict(res, solver.length_m)
    ra, rb = ids.index(solver.name_a), ids.index(solver.name_b)
    el = np.minimum(res.elevation_a_deg, res.elevation_b_deg)
    out = []
    for k in np.flatnonzero(res.eligible & ~res.fixed & np.isfinite(mean)):
        j, jr = col[str(res.sats[k])], col[res.refs[str(res.sats[k])[0]]]
        sd = stec_tecu[rb] - stec_tecu[ra]
        truth = (sd[j] - sd[jr]) * IONO_K_M3_S2 / res.freq_hz[k, 0] ** 2
        out.append((el[k], truth, mean[k], np.sqrt(var[k])))
    return out


class _Timing:
    """Per baseline, time from the solver's start to its first fix and to the SHARES; per arc, time to fix."""

    def __init__(self, t0: int, arcs: bool):
        self.t0 = t0
        self.first: dict[str, dict] = {}  # baseline -> {"first": s, 0.5: s, ...}
        self.arcs = arcs
        self.open: dict[tuple[str, str], dict] = {}
        self.closed: list[dict] = []

    def epoch(self, epoch: int, name: str, res) -> None:
        ref = res.is_reference()
        can = res.eligible & ~ref
        fixed = res.fixed & can
        rec = self.first.setdefault(name, {})
        if fixed.any():
            rec.setdefault("first", epoch - self.t0)
        for share in SHARES:
            if can.sum() >= 4 and fixed.sum() >= share * can.sum():
                rec.setdefault(share, epoch - self.t0)
        if not self.arcs:
            return
        for k, s in enumerate(map(str, res.sats)):
            key = (name, s)
            arc = self.open.get(key)
            if arc is None or arc["last"] != epoch - 1 or s in res.slips:
                if arc is not None:
                    self.closed.append(arc)
                back = arc is not None and arc["eligible"] is not None and epoch - arc["last"] <= BACK_MAX_GAP_S
                arc = self.open[key] = dict(start=epoch, cold=epoch == self.t0, eligible=None, fixed=None,
                                            was_ref=False, last=epoch, back=back)
            arc["last"] = epoch
            arc["was_ref"] |= bool(ref[k] and arc["fixed"] is None)
            if res.eligible[k] and arc["eligible"] is None:
                arc["eligible"] = epoch
            if fixed[k] and arc["fixed"] is None:
                arc["fixed"] = epoch

    def new_arcs(self, back: bool = False):
        """(times to fix of the new arcs, number censored): of the rising satellites, or (`back`) of those back
        after a gap or a slip."""
        arcs = [a for a in self.closed + list(self.open.values())
                if not a["cold"] and a["eligible"] is not None and not a["was_ref"] and a["back"] == back]
        ttf = [a["fixed"] - a["eligible"] for a in arcs if a["fixed"] is not None]
        return np.array(ttf, float), sum(a["fixed"] is None for a in arcs)


@pytest.fixture(scope="module")
def hour():
    world = World(load_scenario("network-70km").model_copy(update={"duration_s": HOUR_S}))
    ids = world.receiver_ids
    stations = {r.id: r.ecef[0] for r in world.receivers if not r.id.startswith("check")}
    solvers = {0: NetworkSolver(stations)}
    timing = {0: _Timing(0, arcs=True)}
    checked, wrong, fractions = 0, [], {}
    model = []  # (elevation [deg], truth DD ionosphere [m], model prediction [m], its sigma [m]), not yet fixed
    col = {s: j for j, s in enumerate(world.sats)}
    for blk in world.epochs():
        per = {r: station_epochs(world, blk, i) for i, r in enumerate(ids)}
        for e in range(len(blk.t_gpst)):
            epoch = int(blk.epoch_index[e])
            if epoch in COLD_STARTS_S:
                solvers[epoch] = NetworkSolver(stations)
                timing[epoch] = _Timing(epoch, arcs=False)
            for t0 in [t0 for t0 in solvers if t0 and epoch >= t0 + COLD_RUN_S]:
                del solvers[t0]
            for t0, net in solvers.items():
                ne = net.update({r: per[r][e] for r in stations}, world.nav)
                for solver in net.solvers.values():
                    res = ne.baselines[solver.name]
                    if res is None:
                        continue
                    timing[t0].epoch(epoch, solver.name, res)
                    if t0 == 0:
                        fractions.setdefault(solver.name, []).append(res.fixed_fraction)
                        if epoch % MODEL_CHECK_EVERY_S == 0 and net.iono_model is not None:
                            model += _model_against_truth(net.iono_model, solver, res, blk.stec_tecu[e], ids, col)
                    # every fixed DD against the truth
                    k = np.flatnonzero(res.fixed & ~res.is_reference())
                    if not k.size:
                        continue
                    truth = true_dd_integers(world, blk, e, ids.index(solver.name_a), ids.index(solver.name_b),
                                             res.sats[k], res.refs)
                    checked += k.size
                    for i in np.flatnonzero(~(truth == res.dd_n[k]).all(axis=1)):
                        wrong.append((t0, epoch, solver.name, str(res.sats[k[i]])))
    cold = {key: np.array([rec.get(key, np.inf) for tm in timing.values() for rec in tm.first.values()], float)
            for key in ("first",) + SHARES}
    ttf, censored = timing[0].new_arcs()
    back_ttf, back_censored = timing[0].new_arcs(back=True)
    out = dict(checked=checked, wrong=wrong, cold=cold, arc_ttf=ttf, arc_censored=censored,
               back_ttf=back_ttf, back_censored=back_censored,
               fraction_after_10_min={k: float(np.mean(v[600:])) for k, v in fractions.items()},
               model=np.array(model))

    def med(v):
        return f"{np.median(v):.0f} s" if np.isfinite(np.median(v)) else "not reached"

    print(f"\nnetwork-70km, 1 h, cold starts at 0/{'/'.join(str(t) for t in COLD_STARTS_S)} s: {checked} fixed DD "
          f"ambiguity-epochs checked, {len(wrong)} wrong. Per baseline from a cold start ({len(cold['first'])}): "
          f"first fix median {med(cold['first'])} (max {cold['first'].max():.0f} s), half of the fixable "
          f"satellites median {med(cold[0.5])}, 80 % median {med(cold[0.8])} ({np.isfinite(cold[0.8]).sum()} "
          f"reached). New arcs: {len(ttf)} fixed, time from eligible to fixed median "
          f"{med(ttf) if len(ttf) else '-'}, {censored} censored. Arcs back after a gap or slip: {len(back_ttf)} "
          f"fixed, median {med(back_ttf) if len(back_ttf) else '-'}, 90 % "
          f"{np.percentile(back_ttf, 90) if len(back_ttf) else float('nan'):.0f} s, {back_censored} censored. "
          f"Mean fixed fraction after 10 min: "
          + ", ".join(f"{k} {v:.2f}" for k, v in out["fraction_after_10_min"].items()))
    low = out["model"][(out["model"][:, 0] < LOW_DEG)]
    print(f"Ionosphere model, satellites not yet fixed at 15-{LOW_DEG:.0f} degrees ({len(low)}): truth DD ionosphere "
          f"{_rms(low[:, 1]) * 100:.1f} cm RMS, model misses by {_rms(low[:, 1] - low[:, 2]) * 100:.1f} cm RMS, "
          f"|miss| / sigma RMS {_rms((low[:, 1] - low[:, 2]) / low[:, 3]):.2f}, max "
          f"{np.max(np.abs(low[:, 1] - low[:, 2]) / low[:, 3]):.2f}")
    return out


def test_an_hour_and_three_cold_starts_without_a_wrong_fix(hour):
    assert hour["checked"] > 100_000
    assert hour["wrong"] == []


def test_time_to_fix_and_fixed_share(hour):
    """Measured with honest (multipath-aware) float covariances, a storm-wide ionosphere prior in the filter and
    the prior in force in the integer decision (the activity-raised default, then the day's level learned from
    the first fixed satellites over the whole network): 2026-11-22, first fix median 12 s (max 17 s; nothing is
    committed before the ionosphere's rate is measured, ~11 s), half of the fixable satellites 27 s, 80 % 53 s,
    all 12 cold starts; mean fixed fraction after 10 min 0.96-0.97. Before the day's level: half 232 s, 80 % on 4 of 12.
    With the network's ionosphere model as the prior of the satellites not fixed yet (same day): first fix 12 s,
    half 27 s, 80 % 30 s, mean fixed fraction after 10 min 1.00 on every baseline."""
    cold = hour["cold"]
    assert np.median(cold["first"]) <= 60, cold["first"]
    assert np.isfinite(cold["first"]).all(), cold["first"]
    assert np.median(cold[0.5]) <= 60, cold[0.5]
    assert all(f > 0.95 for f in hour["fraction_after_10_min"].values()), hour["fraction_after_10_min"]


def test_issue_goal_median_60_s(hour):
    """Issue 5: every baseline's ambiguities fixed within a median 60 s, read as: per baseline and cold start,
    the time until 80 % of the satellites it may fix (above 15 degrees at both stations) are fixed, median over
    the 12 baseline cold starts. (All of them, down to 15 degrees, is not reached within 5 minutes: the low ones
    need minutes of code against correlated multipath, see the new arcs below.)"""
    p80 = hour["cold"][0.8]
    assert np.median(p80) <= 60, p80


def test_the_ionosphere_model_predicts_low_satellites_within_its_sigma(hour):
    """The network's single-layer model (vertical TEC times the stations' mapping-function difference, fitted over
    every baseline's fixed satellites) against the simulator's DD ionosphere of the satellites not yet fixed at
    15-20 degrees: it must miss by less than zero does (the day's prior is centred on zero) and its sigma must
    cover its misses, since it becomes the integer decision's prior."""
    low = hour["model"][hour["model"][:, 0] < LOW_DEG]
    assert len(low) > 500
    miss = low[:, 1] - low[:, 2]
    assert _rms(miss) < 0.9 * _rms(low[:, 1])
    assert _rms(miss / low[:, 3]) <= 1.0
    assert np.max(np.abs(miss) / low[:, 3]) < 4.0


@pytest.mark.xfail(strict=True, raises=AssertionError, reason=(
    "not met in this hour: its rising arcs are slow Galileo risers (4 fixed a median 208 s after reaching 15 degrees, 2 censored); "
    "the figures are in docs/decisions/0061-rising-arc-xfail.md and 0272-presets-as-harsh-as-catnet.md"))
def test_new_satellite_arcs_fix_within_a_median_60_s(hour):
    ttf = hour["arc_ttf"]
    assert len(ttf) and np.median(ttf) <= 60


def test_satellites_back_after_a_receiver_event_fix_within_a_median_60_s(hour):
    """The preset's unflagged resets, slips and gaps (decision 0272): every one the centre detects restarts the
    satellite's ambiguities; the network fixes it again, the issue-5 goal a median 60 s (measured 1 s, 90 % 5 s, 194 arcs, 4 censored),
    and never wrongly (the hour's truth check)."""
    ttf = hour["back_ttf"]
    assert len(ttf) >= 50  # ~0.8 events per satellite-hour at each of four stations
    assert np.median(ttf) <= 60
    assert hour["back_censored"] <= 0.1 * len(ttf)
