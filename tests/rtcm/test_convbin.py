"""RTKLIB's convbin (a tool nobody here wrote) turns an RTCM 3 stream we encoded into RINEX whose
observables equal ours to the message resolution: MSM7 and MSM4, GPS + Galileo + BeiDou."""

from __future__ import annotations

import subprocess

import numpy as np
import pytest

from augnet.gnss.rtcm import RtcmMessage, encode_frame, observables_to_msm
from augnet.gnss.rtcm.observables import RANGE_MS_M
from tests.conftest import require_tool

from .test_observables import random_observables

# 2023-07-11 00:00:00 GPST is Tuesday: GPS/Galileo time of week 2 days; BDT runs 14 s behind GPST.
TOW0_MS = 2 * 86_400_000
BDT_MINUS_GPST_MS = 14_000
EPOCHS = 3
SYSTEMS = ("G", "E", "C")


def parse_rinex3_obs(text: str) -> dict:
    """{(epoch seconds of day, 'G05', 'C1C'): value} from a RINEX 3 observation file (F14.3 fields)."""
    lines = text.splitlines()
    types: dict[str, list[str]] = {}
    i = 0
    cur = None
    while "END OF HEADER" not in lines[i]:
        line = lines[i]
        if line[60:].startswith("SYS / # / OBS TYPES"):
            if line[0] != " ":
                cur = line[0]
                types[cur] = []
            types[cur] += line[7:60].split()
        i += 1
    out = {}
    t = None
    for line in lines[i + 1 :]:
        if line.startswith(">"):
            f = line[1:].split()
            t = round(int(f[3]) * 3600 + int(f[4]) * 60 + float(f[5]), 3)
            continue
        sat = line[:3]
        for k, code in enumerate(types[sat[0]]):
            field = line[3 + 16 * k : 3 + 16 * k + 14]
            if field.strip():
                out[(t, sat, code)] = float(field)
    return out


@pytest.mark.rtklib
@pytest.mark.parametrize("level", [7, 4])
def test_convbin_reads_our_stream(tmp_path, level):
    convbin = require_tool("convbin")
    rng = np.random.default_rng(20230711 + level)
    stream = encode_frame(RtcmMessage(1005, {
        "DF003": 42, "DF021": 0, "DF022": 1, "DF023": 0, "DF024": 1, "DF141": 1, "DF025": -2_148_744.3,
        "DF142": 1, "DF001_1": 0, "DF026": 4_426_641.2, "DF364": 0, "DF027": 4_044_655.9}))
    truth = {}
    for e in range(EPOCHS):
        for s_i, system in enumerate(SYSTEMS):
            # BeiDou on B1I + B2I: RTKLIB 2.4.3 drops B3I (6I) from MSM when writing RINEX
            codes = ("2I", "7I") if system == "C" else None
            obs = random_observables(rng, system, 8, 3 if system != "C" else 2, missing=0.1, sig_codes=codes,
                                     sat_ids=np.arange(3, 35, 4) if system != "C" else np.arange(19, 35, 2))
            tow = TOW0_MS + 1000 * e - (BDT_MINUS_GPST_MS if system == "C" else 0)
            last = s_i == len(SYSTEMS) - 1
            # DF393 = 1 tells the decoder more MSM of this epoch follow (RTKLIB then waits for them)
            msg = observables_to_msm(obs, level, station_id=42, epoch=tow, multiple=0 if last else 1)
            stream += encode_frame(msg)
            truth[(e, system)] = obs
    path = tmp_path / "ours.rtcm3"
    path.write_bytes(stream)
    out = tmp_path / "ours.obs"
    res = subprocess.run([convbin, "-r", "rtcm3", "-tr", "2023/07/11 00:00:00", "-v", "3.04", "-f", "3", "-od", "-os",
                          "-o", str(out), str(path)], capture_output=True, text=True, timeout=60)
    assert out.exists(), res.stderr
    rinex = parse_rinex3_obs(out.read_text())
    pr_tol = (2.0 ** -29 if level == 7 else 2.0 ** -24) * RANGE_MS_M / 2 + 0.0005  # + RINEX F14.3 rounding
    ph_tol_m = (2.0 ** -31 if level == 7 else 2.0 ** -29) * RANGE_MS_M / 2
    compared = 0
    for (e, system), obs in truth.items():
        lam = obs.wavelengths_m
        for i, sat in enumerate(obs.sat_ids):
            name = f"{system}{int(sat):02d}"
            for j, code in enumerate(obs.rinex_codes):
                t = float(e)
                pr = rinex.get((t, name, "C" + code))
                if np.isnan(obs.pseudorange_m[i, j]):
                    assert pr is None
                    continue
                assert pr is not None, (e, name, code)
                assert abs(pr - obs.pseudorange_m[i, j]) <= pr_tol
                cp = rinex.get((t, name, "L" + code))
                assert cp is not None and abs(cp - obs.phase_cycles[i, j]) <= ph_tol_m / lam[j] + 0.0005
                snr = rinex.get((t, name, "S" + code))
                assert snr is not None and abs(snr - obs.cnr_dbhz[i, j]) <= 0.5 + 0.25
                if level == 7:
                    dop = rinex.get((t, name, "D" + code))
                    # RTKLIB 2.4.3 keeps Doppler as a C float (obsd_t.D): add its rounding, 2^-24 relative
                    tol = 0.00005 / lam[j] + 0.0005 + abs(dop) * 2.0**-23
                    assert dop is not None and abs(dop - obs.doppler_hz[i, j]) <= tol
                compared += 1
    assert compared > 100
