"""Onboard RTK with receiver antenna models: base and rover phase-centre offsets from their calibrations and
RINEX antenna heights, so the base position and the solution are the markers'."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from augnet.gnss.antex import AntennaSetup, FrequencyModel, ReceiverAntenna, read_antex
from augnet.gnss.ephemeris import NavigationData
from augnet.gnss.geometry import ecef_to_enu, enu_to_ecef, geodetic_deg_to_ecef
from augnet.onboard.inputs import antenna_setup
from augnet.onboard.postprocess import process
from augnet.onboard.rtk import RtkOptions, Status
from tests.gnss.test_antex import tiny_antex
from tests.onboard.synth import simulate, visible_sats

BASE = geodetic_deg_to_ecef(35.1347, 136.9776, 105.0)
T0 = 1403252400.0
N_EPOCHS = 10


def _antenna(up_m: float) -> ReceiverAntenna:
    zen = np.arange(0.0, 91.0, 5.0)
    f = FrequencyModel(np.array([0.0, 0.0, up_m]), zen, np.zeros(len(zen)))
    return ReceiverAntenna("TEST-OFFSET     NONE", {"G01": f, "G02": f})


@pytest.fixture(scope="module")
def nav(shared_data):
    from augnet.gnss.rinex import read_nav

    return NavigationData(read_nav(shared_data / "rinex/static-1m-2024/base.nav").ephemerides)


def _up(p, up):
    return p + enu_to_ecef(np.array([0.0, 0.0, up]), p).reshape(3)


@pytest.mark.shared_data
def test_base_and_rover_antennas_put_the_solution_on_the_marker(nav):
    sats = [s for s in visible_sats(nav, BASE, T0) if s[0] == "G"]
    marker = BASE + enu_to_ecef(np.array([800.0, 600.0, 3.0]), BASE).reshape(3)
    t = T0 + np.arange(float(N_EPOCHS))
    # the receivers observe at their phase centres: base 7 cm above its marker (all PCO), rover 5 cm of
    # antenna height plus 6 cm of PCO
    base, _ = simulate(nav, sats, t, _up(BASE, 0.07), seed=31, with_atmosphere=False)
    rover, _ = simulate(nav, sats, t, _up(marker, 0.11), seed=32, with_atmosphere=False)
    opt = RtkOptions(systems=("G",), ionosphere="off")
    base_ant = AntennaSetup(_antenna(0.07))
    rover_ant = AntennaSetup(_antenna(0.06), np.array([0.0, 0.0, 0.05]))
    modelled = list(process(rover, base, nav, BASE, opt, base_antenna=base_ant, rover_antenna=rover_ant))
    plain = list(process(rover, base, nav, BASE, opt))
    assert all(s.status == Status.FIX for s in modelled + plain)
    enu_m = np.array([ecef_to_enu(s.position_m - marker, marker).reshape(3) for s in modelled])
    enu_p = np.array([ecef_to_enu(s.position_m - marker, marker).reshape(3) for s in plain])
    assert np.abs(enu_m).max() < 0.01  # the marker
    # without the models the solution is where the rover's phase centre is relative to the base's: 11 - 7 cm up
    assert np.median(enu_p[:, 2]) == pytest.approx(0.04, abs=0.01)


def test_antenna_setup_from_the_header(tmp_path):
    p = tmp_path / "tiny.atx"
    p.write_text("\n".join(tiny_antex()) + "\n")
    atx = read_antex(p)
    from augnet.onboard.observations import ObsArrays

    obs = ObsArrays(np.zeros(1), ["G01"], {}, antenna_type="TEST1           NONE", antenna_delta_hen_m=(0.054, 0.0, 0.0))
    setup, note = antenna_setup(obs, atx, "base")
    assert setup.antenna.type_name == "TEST1" and setup.delta_neu_m.tolist() == [0.0, 0.0, 0.054]
    assert "TEST1" in note and "0.0540" in note
    # at the zenith: antenna height plus the up offset
    assert setup.correction_m([0.0], [np.pi / 2], ["G01"], [["1C", "2W"]])[0] == pytest.approx([0.104, 0.114])
    unknown = dataclasses.replace(obs, antenna_type="NOPE", antenna_delta_hen_m=(0.0, 0.0, 0.0))
    setup, note = antenna_setup(unknown, atx, "rover")
    assert setup is None and "no calibration" in note
