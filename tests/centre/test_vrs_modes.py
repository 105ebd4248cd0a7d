"""What a VRS carries per satellite (vrs_modes.py): the float model only where its sigma is clearly below the
single-base error it replaces, and labels and counts that say so."""

import numpy as np
import pytest

from augnet.centre.vrs_modes import (FLOAT_MODEL, FLOAT_MODEL_MARGIN, MODE_LABELS, NETWORK, SINGLE_BASE, ModeTally,
                                     select_modes, single_base_sigma_m)


def test_single_base_sigma_grows_with_distance_and_level():
    s = single_base_sigma_m([0.0, 10_000.0, 40_000.0], 2.0)
    assert s[0] == 0.0
    assert s[2] == pytest.approx(4 * s[1])
    assert s[1] == pytest.approx(2.0e-6 * 10_000.0)  # 2 ppm of 10 km = 2 cm


def test_single_base_sigma_rejects_bad_input():
    with pytest.raises(ValueError):
        single_base_sigma_m([1.0], float("nan"))
    with pytest.raises(ValueError):
        single_base_sigma_m([-1.0], 1.0)


def test_float_model_only_when_clearly_below_single_base():
    corrected = np.array([[True, False, False, False, False]])
    single = np.array([0.04])  # 4 cm: 2 ppm at 20 km
    below = FLOAT_MODEL_MARGIN * 0.04
    fs = np.array([[0.001, 0.5 * below, 1.01 * below, np.nan, 0.10]])
    modes, sigma = select_modes(corrected, single, fs, float_model=True)
    assert modes[0].tolist() == [NETWORK, FLOAT_MODEL, SINGLE_BASE, SINGLE_BASE, SINGLE_BASE]
    assert sigma[0, 1] == pytest.approx(0.5 * below)  # the float model's own sigma
    assert sigma[0, 2:].tolist() == pytest.approx([0.04] * 3)  # the single-base error it keeps
    assert np.isnan(sigma[0, 0])  # network sigma not given: not invented


def test_float_model_off_by_default_and_network_wins():
    corrected = np.array([[True, False]])
    fs = np.array([[0.0001, 0.0001]])
    modes, _ = select_modes(corrected, [0.05], fs)
    assert modes[0].tolist() == [NETWORK, SINGLE_BASE]
    modes, _ = select_modes(corrected, [0.05], fs, float_model=True)
    assert modes[0].tolist() == [NETWORK, FLOAT_MODEL]  # a fixed satellite never degrades to float


def test_near_master_float_model_cannot_beat_zero_error():
    # at the master the single-base error is nil: no float model can be below it
    modes, _ = select_modes([[False]], single_base_sigma_m([0.0], 3.0), [[1e-6]], float_model=True)
    assert modes[0, 0] == SINGLE_BASE


def test_margin_out_of_range_is_an_error():
    with pytest.raises(ValueError):
        select_modes([[False]], [0.01], [[0.001]], float_model=True, margin=0.0)


def test_tally_counts_and_labels():
    t = ModeTally()
    t.add(np.array([NETWORK, NETWORK, SINGLE_BASE], np.int8), np.array([np.nan, np.nan, 0.03]))
    t.add(np.array([SINGLE_BASE, FLOAT_MODEL], np.int8), np.array([0.05, 0.01]))
    assert t.counts == {NETWORK: 2, FLOAT_MODEL: 1, SINGLE_BASE: 2}
    assert t.epochs == {NETWORK: 1, FLOAT_MODEL: 1, SINGLE_BASE: 2}
    lines = t.lines()
    assert [ln.split(":")[0] for ln in lines] == [f"VRS carries {m}" for m in MODE_LABELS.values()]
    assert "not estimated" in lines[0]  # the network's sigma is not claimed
    assert "median 4.0 cm" in lines[2]
    with pytest.raises(ValueError):
        t.add(np.array([NETWORK]), np.array([0.1, 0.2]))
