"""RTKLIB's MSM7 (pyrtklib) and ours agree both ways on the same observables within MSM7 resolution (issue 17)."""

import numpy as np
import pytest

from augnet.bench import rtcm, rtklib_peer
from augnet.gnss.rtcm import Observables, decode, encode_frame, msm_to_observables, observables_to_msm

p, why = rtklib_peer.load()
pytestmark = pytest.mark.skipif(p is None, reason=why)

C = 299_792_458.0
# MSM7 resolutions (RTCM 10403.3 DF405/DF406/DF404/DF408), half a step is the largest rounding error
HALF_PR_M = 0.5 * 2**-29 * 1e-3 * C
HALF_PHASE_M = 0.5 * 2**-31 * 1e-3 * C
HALF_RATE_MS = 0.5 * 0.0001
HALF_CNR = 0.5 * 2**-4


def _inputs():
    sat, sig, sid, ep, pr, cp, dop, cnr, lock, half = rtcm.sample_inputs(2)
    return sat, sig, int(sid[0]), int(ep[0]), pr[0], cp[0], dop[0], cnr[0], lock[0], half[0]


def test_ours_decodes_rtklibs_msm7_to_the_same_observables():
    sat, sig, sid, tow, pr, cp, dop, cnr, lock, half = _inputs()
    frame = rtklib_peer.RtklibMsm7(p, sat, sig, pr, cp, dop, cnr, tow).frame()
    o = msm_to_observables(decode(frame[3:-3]))
    lam = o.wavelengths_m
    assert np.all(np.abs(o.pseudorange_m - pr) <= HALF_PR_M + 1e-9)
    assert np.all(np.abs(o.phase_cycles - cp) * lam <= HALF_PHASE_M + HALF_PR_M)  # rough range shared
    assert np.all(np.abs(o.doppler_hz - dop) * lam <= HALF_RATE_MS + 1e-3)  # RTKLIB holds D as float32
    assert np.all(np.abs(o.cnr_dbhz - cnr) <= HALF_CNR + 1e-3)


def test_rtklib_decodes_ours_to_the_same_observables():
    sat, sig, sid, tow, pr, cp, dop, cnr, lock, half = _inputs()
    ours = encode_frame(observables_to_msm(Observables("G", sat, sig, pr, cp, dop, cnr, lock, half), 7, sid, tow))
    got = rtklib_peer.decode_with_rtklib(p, ours, tow)
    codes = [getattr(p, rtklib_peer._GPS_CODES[int(s)]) for s in sig]
    lam = Observables("G", sat, sig, pr, cp, dop, cnr, lock, half).wavelengths_m
    assert len(got) == pr.size
    for i, prn in enumerate(sat):
        for j, code in enumerate(codes):
            P, L, D, snr = got[(p.satno(p.SYS_GPS, int(prn)), code)]
            assert abs(P - pr[i, j]) <= HALF_PR_M + 1e-9
            assert abs(L - cp[i, j]) * lam[j] <= HALF_PHASE_M + HALF_PR_M
            assert abs(D - dop[i, j]) * lam[j] <= HALF_RATE_MS + 1e-3
            assert abs(snr - cnr[i, j]) <= HALF_CNR + 1e-3
