"""Which VRS epochs are network-corrected (`postprocess.network_satellites`): double differences per system,
on constructed satellite sets (decision 0160). The same rule on the real GPS-only catnet network at UPC1 is
tested in test_real_network_catnet.py, on the network run it shares with the other real-network tests."""

from __future__ import annotations

import pytest

from augnet.centre.postprocess import MIN_NETWORK_DD, network_satellites


def _sats(spec: str) -> set[str]:
    """'G5 E2' -> {'G01'..'G05', 'E01', 'E02'}."""
    return {f"{part[0]}{k:02d}" for part in spec.split() for k in range(1, int(part[1:]) + 1)}


@pytest.mark.parametrize("spec, carried", [
    ("G6", "G6"),  # one system: 5 DD, the least a network epoch has
    ("G5", ""),  # 4 DD: single-base
    ("G5 E1", ""),  # a lone Galileo satellite forms no DD and is no help
    ("G6 E1", "G6"),  # ... and is left out of the network epoch
    ("G4 C3", "G4 C3"),  # 3 + 2 DD across two systems
    ("G3 E3 C2", "G3 E3 C2"),  # 2 + 2 + 1
    ("G3 E2 C1", ""),  # 2 + 1, C left out
    ("G4 E3 C3", "G4 E3 C3"),  # decision 0007's ten across three systems: 7 DD
    ("", ""),
])
def test_network_epoch_counts_double_differences_per_system(spec, carried):
    assert network_satellites(_sats(spec)) == _sats(carried)


def test_the_rule_is_the_dd_count():
    for n in range(1, 12):  # one system: n - 1 DD
        assert bool(network_satellites(_sats(f"G{n}"))) == (n - 1 >= MIN_NETWORK_DD)
