"""The one check of the network's fixed DD integers against the simulator's truth (stations/network_truth.py)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from stations.network_truth import true_dd_integers


def _world_block():
    sats = ["G01", "G02", "G03", "E01", "E02"]
    rng = np.random.default_rng(7)
    amb = rng.integers(-1000, 1000, size=(1, 3, len(sats), 3)).astype(float)  # epoch, receiver, sat, signal
    return SimpleNamespace(sats=sats), SimpleNamespace(ambiguity_cyc=amb), amb[0]


def test_dd_is_second_receiver_minus_first_satellite_minus_its_systems_reference():
    world, block, amb = _world_block()
    got = true_dd_integers(world, block, 0, 0, 2, ["G02", "E02"], {"G": "G03", "E": "E01"})
    want = np.array([(amb[2, 1, :2] - amb[0, 1, :2]) - (amb[2, 2, :2] - amb[0, 2, :2]),
                     (amb[2, 4, :2] - amb[0, 4, :2]) - (amb[2, 3, :2] - amb[0, 3, :2])])
    assert got.shape == (2, 2)
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(true_dd_integers(world, block, 0, 2, 0, ["G02"], {"G": "G03"}), -want[:1])


def test_a_satellite_against_itself_is_zero():
    world, block, _ = _world_block()
    assert not true_dd_integers(world, block, 0, 1, 2, ["G01"], {"G": "G01"}).any()
