"""The baseline filter's float solution is honest: its DD wide-lane errors against the simulator's truth are the
size its covariance says. The success rate, and with it every integer the network fixes, rests on that; with
white-noise weights for the stations' minutes-long multipath the same errors came out 2-3.5 times larger than
the covariance after a minute, and cold starts fixed wrong integers."""

from __future__ import annotations

import numpy as np
import pytest

from augnet.centre.baseline_config import BaselineConfig
from augnet.centre.baseline_state import N1
from augnet.centre.network import NetworkSolver
from stations.scenario import load_scenario
from stations.world import World
from tests.centre.simdata import station_epochs, truth_dd_ambiguity

pytestmark = pytest.mark.slow

DURATION_S = 240


def _normalized_errors(config: BaselineConfig | None) -> np.ndarray:
    world = World(load_scenario("network-70km").model_copy(update={"duration_s": DURATION_S}))
    ids = world.receiver_ids
    stations = {r.id: r.ecef[0] for r in world.receivers if not r.id.startswith("check")}
    net = NetworkSolver(stations, config=config)
    z = []
    for blk in world.epochs():
        per = {r: station_epochs(world, blk, i) for i, r in enumerate(ids)}
        for e in range(len(blk.t_gpst)):
            ne = net.update({r: per[r][e] for r in stations}, world.nav)
            if blk.epoch_index[e] % 10:
                continue
            for sv in net.solvers.values():
                res = ne.baselines[sv.name]
                ra, rb = ids.index(sv.name_a), ids.index(sv.name_b)
                for k, s in enumerate(map(str, res.sats)):
                    ref = res.refs[s[0]]
                    if s == ref or res.fixed[k] or not res.eligible[k]:
                        continue
                    st = sv.state
                    d = np.zeros(len(st.x))  # the wide lane N1 - N2 of the DD (s - ref)
                    d[[st.index(s) + N1, st.index(ref) + N1 + 1]] = 1.0
                    d[[st.index(s) + N1 + 1, st.index(ref) + N1]] = -1.0
                    n = truth_dd_ambiguity(world, blk, e, ra, rb, s, ref)
                    z.append((d @ st.x - (n[0] - n[1])) / np.sqrt(d @ st.P @ d))
    return np.array(z)


@pytest.fixture(scope="module")
def normalized_errors():
    """The filter told the world's L2 code noise (the preset's second_signal_code_factor)."""
    factor = load_scenario("network-70km").errors.noise.second_signal_code_factor
    return _normalized_errors(BaselineConfig(code_sigma_second_factor=factor))


def _check(z):
    assert z.size > 500  # every 10th epoch's unfixed satellites: 820 in the harsher preset (decision 0272)
    rms = float(np.sqrt(np.mean(z**2)))
    print(f"\nfloat DD wide lanes (unfixed, eligible), {z.size} samples: error / sigma RMS {rms:.2f}, "
          f"|z| > 3: {np.mean(np.abs(z) > 3):.2%}")
    assert 0.4 <= rms <= 1.4  # measured 0.65 (0.60 before 0272): on the safe side (the ionosphere prior is wide)
    assert np.mean(np.abs(z) > 3) < 0.01


def test_float_wide_lane_errors_match_the_covariance(normalized_errors):
    _check(normalized_errors)


@pytest.mark.xfail(strict=True, raises=AssertionError, reason=(
    "the default filter weights L2 code as L1 code; the preset's L2 code is 1.5 times noisier (as real L2 P(Y)): "
    "1.6 % of |z| > 3, decision 0272"))
def test_float_wide_lane_errors_match_the_covariance_with_the_default_code_weights():
    _check(_normalized_errors(None))
