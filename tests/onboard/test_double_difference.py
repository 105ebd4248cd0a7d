"""The DD measurement model's pieces: reference choice, index arrays, rows, masks, slip attribution."""

from __future__ import annotations

import numpy as np
import pytest

from augnet.onboard.double_difference import (
    DDIndex,
    Group,
    Rows,
    SingleDifferences,
    choose_groups,
    dd_index,
    dd_rows,
    phase_residuals,
    slipped_keys,
)

SATS = ["G01", "G02", "G03", "E11", "E12"]
SYS = np.array([s[0] for s in SATS])
EL = np.radians([60.0, 40.0, 20.0, 50.0, 70.0])


def test_reference_is_the_highest_satellite_with_an_established_ambiguity():
    ok = np.ones((5, 1), bool)
    amb_var = np.full((5, 1), 100.0)
    groups = choose_groups(("G", "E"), SYS, ok, EL, 1, amb_var)
    assert [(g.sats, g.slot) for g in groups] == [([0, 1, 2], 0), ([4, 3], 0)]
    amb_var[1, 0] = 0.01  # G02 established: it becomes the reference although G01 is higher
    groups = choose_groups(("G", "E"), SYS, ok, EL, 1, amb_var)
    assert groups[0].sats == [1, 0, 2]
    ok[3, 0] = False  # a system with one usable satellite has no DD
    assert len(choose_groups(("G", "E"), SYS, ok, EL, 1, amb_var)) == 1


def _epoch():
    groups = [Group([0, 1, 2], 0), Group([4, 3], 0)]
    state = {0: 3, 1: 4, 2: 5, 3: 6, 4: 7}  # SD ambiguity state index per satellite
    dd = dd_index(groups, lambda k, f: state[k])
    rng = np.random.default_rng(1)
    los = rng.normal(size=(5, 3))
    los /= np.linalg.norm(los, axis=1)[:, None]
    sd = SingleDifferences(rng.normal(size=(5, 1)), rng.normal(size=(5, 1)), los, EL)
    return dd, sd


def test_dd_index_and_rows():
    dd, sd = _epoch()
    assert dd.k.tolist() == [1, 2, 3] and dd.ref.tolist() == [0, 0, 4] and dd.group.tolist() == [0, 0, 1]
    assert dd.i.tolist() == [4, 5, 6] and dd.iref.tolist() == [3, 3, 7] and dd.ion is None
    wl = np.full((5, 1), 0.19)
    x = np.arange(8.0)
    rows = dd_rows(dd, sd, wl, np.ones((5, 1)), np.full((5, 1), 1e-4), x, 100.0)
    assert rows.H.shape == (6, 8) and rows.kind.tolist() == [1, 1, 1, 0, 0, 0]
    # the phase innovation is the DD phase minus the DD ambiguities in metres
    expect = (sd.phase[1, 0] - sd.phase[0, 0]) - 0.19 * (x[4] - x[3])
    assert rows.v[0] == pytest.approx(expect, abs=1e-12)
    # rows of one group share the reference's noise; code is the phase noise times the ratio squared
    assert rows.R[0, 1] == 1e-4 and rows.R[0, 2] == 0.0 and rows.R[3, 3] == 2e-4 * 100.0**2
    # the phase residuals of the state the rows were built for are the phase innovations
    np.testing.assert_allclose(phase_residuals(dd, np.arange(3), sd, wl, np.ones((5, 1)), x[:3], x), rows.v[:3])


def test_select_and_about():
    rows = Rows(np.array([1.0, 2.0, 3.0]), np.arange(12.0).reshape(3, 4), np.diag([1.0, 2.0, 3.0]), np.array([1, 1, 0]))
    assert rows.select(None) is rows and rows.select(np.ones(3, bool)) is rows
    kept = rows.select(np.array([True, False, True]))
    assert kept.v.tolist() == [1.0, 3.0] and kept.R.tolist() == [[1.0, 0.0], [0.0, 3.0]] and kept.kind.tolist() == [1, 0]
    moved = rows.about(np.array([1.0, 0.0, 0.0]), np.zeros(3))
    np.testing.assert_array_equal(moved.v, rows.v - rows.H[:, 0])


def test_a_slip_is_put_on_the_satellite_or_on_a_reference_whose_rows_all_fail():
    dd = DDIndex(np.array([1, 2, 3]), np.array([0, 0, 0]), np.zeros(3, int), np.zeros(3, int),
                 np.array([4, 5, 6]), np.array([3, 3, 3]), None, None)
    known = np.ones(3, bool)
    sats = ["G01", "G02", "G03", "G04"]
    assert slipped_keys(np.array([False, True, False]), dd, known, sats) == {("G03", 0)}
    assert slipped_keys(np.array([True, True, False]), dd, known, sats) == {("G01", 0)}
