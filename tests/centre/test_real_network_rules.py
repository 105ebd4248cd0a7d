"""The rules of RTKLIB's second opinion (augnet/centre/rtklib_compare.py) on small hand-made cases: its trace and
status read back in its double-difference order, and what counts as a disagreement."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from augnet.centre import rtklib_compare as rc

T0 = 952905600.0  # 2010-03-18 00:00:00 GPST
WEEK, TOW0 = 1575, 345600.0


def _sat_line(t, sat, frq, fix, lock, slip=0):
    return (f"$SAT,{WEEK},{TOW0 + t - T0:.3f},{sat},{frq},0.0,45.0,0.0,0.0,1,45.0,{fix},{slip},{lock},0,0,0\n")


def test_trace_keeps_only_accepted_integer_vectors(tmp_path):
    trace = tmp_path / "x.trace"
    trace.write_text(
        "3 rtkpos  : time=2010/03/18 00:00:00.000 n=12\n"
        "4 N(1)=      5.000     -7.000\n"
        "2 00:00:00.00: ambiguity validation failed (nb=2 ratio=1.20 s=0.14/0.17)\n"
        "3 rtkpos  : time=2010/03/18 00:00:30.000 n=12\n"
        "4 N(1)=      6.000     -7.000\n"
        "4 N(2)=      6.000     -8.000\n"
        "3 resamb : validation ok (nb=2 ratio=3.50 s=0.10/0.35)\n")
    got = rc.read_accepted_integers(trace)
    assert list(got) == [T0 + 30.0]
    assert got[T0 + 30.0].tolist() == [6.0, -7.0]


def test_integer_vector_follows_rtklib_order_reference_first_by_satellite_number(tmp_path):
    stat = tmp_path / "x.stat"
    t = T0 + 30.0
    # L1: G02 (reference), G10, G05 fixed; G07 float. L2: G05 (reference), G10.
    stat.write_text("".join([_sat_line(t, "G10", 1, 2, 5), _sat_line(t, "G02", 1, 3, 5), _sat_line(t, "G05", 1, 2, 5),
                             _sat_line(t, "G07", 1, 1, 5), _sat_line(t, "G10", 2, 2, 5), _sat_line(t, "G05", 2, 3, 5),
                             _sat_line(t, "G02", 2, 1, 5)]))
    status = rc.read_sat_status(stat)
    # entries: reference minus satellite, L1 (G05, G10) then L2 (G10)
    fixed = rc.rtklib_fixed(status, {t: np.array([3.0, -4.0, 9.0])})
    assert fixed[t][0] == {"G02": 0, "G05": -3, "G10": 4}
    assert fixed[t][1] == {"G05": 0, "G10": -9}
    with pytest.raises(ValueError):
        rc.rtklib_fixed(status, {t: np.array([3.0, -4.0])})


def _ours(rows):
    """rows: (t, {sat: (N1, N2)}, slips)."""
    ours = rc.OurIntegers()
    for t, fixed, slips in rows:
        sats = np.array(sorted(fixed))
        ours.add(SimpleNamespace(t_gpst=t, sats=sats, slips=slips, fixed=np.ones(len(sats), bool),
                                 dd_n=np.array([fixed[s] for s in sats], float)))
    return ours


def _theirs(rows):
    """rows: (t, {sat: N1}) on L1 only, every satellite locked since the start."""
    fixed = {t: {0: dict(v)} for t, v in rows}
    arcs = {t: {(s, 0): 1 for s in v} | {(s, 1): 1 for s in v} for t, v in rows}
    return fixed, arcs


def test_same_integers_through_a_reference_change_agree():
    # ours against G01 then against G03; RTKLIB against G02: N(i) - N(j) is the same number throughout
    ours = _ours([(T0, {"G01": (0, 0), "G02": (5, 1), "G03": (-2, 4)}, []),
                  (T0 + 30, {"G01": (2, -4), "G02": (7, -3), "G03": (0, 0)}, [])])
    theirs, arcs = _theirs([(T0, {"G01": -5, "G02": 0, "G03": -7}), (T0 + 30, {"G01": -5, "G02": 0, "G03": -7})])
    c = rc.compare(ours, theirs, arcs)
    assert (c.pair_epochs, c.agreements, c.disagreements, c.offset_arcs) == (6, 6, 0, 0)


def test_an_integer_that_changes_within_an_arc_is_a_disagreement():
    rows = [(T0 + 30 * k, {"G01": (0, 0), "G02": (5 if k != 2 else 6, 1)}, []) for k in range(4)]
    theirs, arcs = _theirs([(T0 + 30 * k, {"G01": 0, "G02": 5}) for k in range(4)])
    c = rc.compare(_ours(rows), theirs, arcs)
    assert (c.pair_epochs, c.disagreements, c.offset_arcs) == (4, 1, 0)


def test_a_constant_offset_over_an_arc_is_reported_apart():
    rows = [(T0 + 30 * k, {"G01": (0, 0), "G02": (6, 1)}, []) for k in range(3)]
    theirs, arcs = _theirs([(T0 + 30 * k, {"G01": 0, "G02": 5}) for k in range(3)])
    c = rc.compare(_ours(rows), theirs, arcs)
    assert (c.disagreements, c.offset_arcs) == (0, 1)


def test_a_slip_on_our_side_starts_a_new_arc():
    # G02 slips at the third epoch and comes back with other integers; so does RTKLIB's state (its new arc)
    rows = [(T0, {"G01": (0, 0), "G02": (5, 1)}, []), (T0 + 30, {"G01": (0, 0), "G02": (5, 1)}, []),
            (T0 + 60, {"G01": (0, 0), "G02": (9, 2)}, ["G02"]), (T0 + 90, {"G01": (0, 0), "G02": (9, 2)}, [])]
    theirs = {T0 + 30 * k: {0: {"G01": 0, "G02": 5 if k < 2 else 9}} for k in range(4)}
    arcs = {T0 + 30 * k: {("G01", 0): 1, ("G02", 0): 2 if k < 2 else 3} for k in range(4)}
    c = rc.compare(_ours(rows), theirs, arcs)
    assert (c.arcs, c.pair_epochs, c.disagreements, c.offset_arcs) == (2, 4, 0, 0)


def test_rtklib_arcs_break_on_a_slip_or_a_lock_reset(tmp_path):
    stat = tmp_path / "x.stat"
    stat.write_text("".join([_sat_line(T0, "G01", 1, 2, 7), _sat_line(T0 + 30, "G01", 1, 2, 8),
                             _sat_line(T0 + 60, "G01", 1, 1, 0), _sat_line(T0 + 90, "G01", 1, 1, 1),
                             _sat_line(T0 + 120, "G01", 1, 1, 2, slip=1)]))
    arcs = rc.rtklib_arcs(rc.read_sat_status(stat))
    ids = [arcs[T0 + 30 * k][("G01", 0)] for k in range(5)]
    assert ids[0] == ids[1] and ids[2] == ids[3] and len(set(ids)) == 3
