"""The VRS between network epochs (vrs_densify.py), judged on a real 1 Hz receiver decimated to 30 s.

UPC2 (Septentrio PolaRx2, catnet-2010-077) logs at 1 Hz: kept at every 30th second as if it were a 30 s station,
its epochs in between are interpolated and set beside the ones it really observed. The geometry is recomputed at
each epoch, so only the residual's curvature over 30 s remains (satellite clocks, atmosphere, multipath).
"""

from __future__ import annotations

import gzip
import shutil

import numpy as np
import pytest

from augnet.centre.observations import from_obsdata
from augnet.centre.vrs_densify import densify
from augnet.gnss.constants import SPEED_OF_LIGHT_M_S
from augnet.gnss.ephemeris import NavigationData
from augnet.gnss.rinex import read_nav, read_obs
from augnet.gnss.rinex.obs import to_rinex3_types

pytestmark = [pytest.mark.shared_data]

CAT = "rinex/catnet-2010-077"
SPAN_S = (5 * 3600.0, 5 * 3600.0 + 600.0)  # ten minutes of the day (GPS seconds of day)
NETWORK_S = 30.0
# Interpolated L1 phase against the observed, between satellites: measured 4.6 mm rms (2026-12-04); a wrong
# geometry (not recomputed, or an ephemeris upload inside an interval) gives centimetres to metres.
MAX_PHASE_RMS_M = 0.008
CLOCK_OFFSETS_S = (0.0, 1e-4, -1e-3)  # the receiver clock the geometry assumes must not matter


@pytest.fixture(scope="module")
def upc2(shared_data, tmp_path_factory):
    d = tmp_path_factory.mktemp("densify")

    def plain(name):
        out = d / name.removesuffix(".gz")
        with gzip.open(shared_data / CAT / name, "rb") as src, open(out, "wb") as dst:
            shutil.copyfileobj(src, dst)
        return out

    nav = NavigationData(read_nav(plain("brdc0770.10n.gz")).ephemerides)
    obs = to_rinex3_types(read_obs(plain("UPC20770.10o.gz")))
    t = np.asarray(obs.times)
    rows = np.flatnonzero((t % 86400.0 >= SPAN_S[0]) & (t % 86400.0 < SPAN_S[1]))
    eps = {round(float(t[i]), 3): from_obsdata(obs, int(i), "UPC2") for i in rows}
    network = [eps[k] for k in sorted(eps) if k % NETWORK_S == 0.0]
    return {"nav": nav, "all": eps, "network": network, "point": np.array(obs.header.approx_position_m)}


def _phase_errors(out, observed):
    err = []
    for ep in out:
        if ep.t_gpst % NETWORK_S == 0.0:
            continue
        tru = observed[round(ep.t_gpst, 3)]
        _, ia, ib = np.intersect1d(ep.sats, tru.sats, return_indices=True)
        d = (ep.phase_cyc[ia, 0] - tru.phase_cyc[ib, 0]) * SPEED_OF_LIGHT_M_S / ep.freq_hz[ia, 0]
        d = d[np.isfinite(d)]
        if len(d) >= 2:
            err.append(d - d.mean())  # between satellites: the receiver clock is the VRS master's anyway
    return np.concatenate(err)


@pytest.mark.parametrize("clock_s", CLOCK_OFFSETS_S)
def test_interpolated_epochs_reproduce_the_withheld_observations(upc2, clock_s):
    net = upc2["network"]
    out, added = densify(net, [clock_s] * len(net), ["UPC2"] * len(net), upc2["point"], upc2["nav"], 1.0,
                         NETWORK_S)
    assert added == (len(net) - 1) * (int(NETWORK_S) - 1)
    times = np.array([ep.t_gpst for ep in out])
    assert np.all(np.diff(times) == 1.0)
    err = _phase_errors(out, upc2["all"])
    assert np.sqrt(np.mean(err ** 2)) < MAX_PHASE_RMS_M
    # the network's own epochs are written unchanged
    assert out[0] is net[0] and out[int(NETWORK_S)] is net[1]


def test_no_satellite_across_a_loss_of_lock_and_no_gap_bridged(upc2):
    net = list(upc2["network"][:4])
    slipped = net[1].sats[0]
    lli = net[1].lli.copy()
    lli[0, 0] |= 1
    net[1] = type(net[1])(net[1].station, net[1].t_gpst, net[1].sats, net[1].code_m, net[1].phase_cyc, lli,
                          net[1].cnr_dbhz, net[1].freq_hz, net[1].codes)
    net = net[:2] + net[3:]  # a 60 s gap between the second and the third epoch
    out, added = densify(net, [0.0] * len(net), ["UPC2"] * len(net), upc2["point"], upc2["nav"], 1.0, NETWORK_S)
    between_first = [ep for ep in out if net[0].t_gpst < ep.t_gpst < net[1].t_gpst]
    assert len(between_first) == int(NETWORK_S) - 1 == added
    assert all(slipped not in ep.sats for ep in between_first)
    assert not [ep for ep in out if net[1].t_gpst < ep.t_gpst < net[2].t_gpst]
    # nor across a change of master (another receiver clock and other ambiguities)
    out, added = densify(net[:2], [0.0, 0.0], ["A", "B"], upc2["point"], upc2["nav"], 1.0, NETWORK_S)
    assert added == 0 and len(out) == 2
