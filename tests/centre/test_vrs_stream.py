"""VRS stream details a rover relies on: the station is flagged as computed, and a satellite whose
correction source changes restarts its lock (its phase steps by the residual atmosphere)."""

from __future__ import annotations

import io

import numpy as np
from pyrtcm import RTCMReader

from augnet.centre.vrs import VrsEpoch
from augnet.centre.vrs_stream import VrsStreamEncoder
from augnet.gnss.ephemeris import NavigationData
from augnet.gnss.rtcm.codec import MessageReader
from augnet.gnss.rtcm.msm import MsmMessage
from augnet.gnss.rtcm.observables import msm_to_observables

T0 = 1_479_350_000.0
F1, F2 = 1575.42e6, 1227.60e6


def _epoch(t: float, corrected_g02: bool) -> VrsEpoch:
    sats = np.array(["G01", "G02"])
    rng = np.random.default_rng(int(t))
    code = (2.1e7 + np.array([[0.0, 2.0], [1e5, 1e5 + 3.0]]))[None] + rng.normal(0, 0.3, (1, 2, 2))
    lam = 299792458.0 / np.array([F1, F2])
    phase = code / lam + 0.01 * (t - T0)
    return VrsEpoch(t_gpst=t, points_ecef_m=np.array([[-2.2e6, 4.4e6, 4.0e6]]), master=["STA1"], sats=sats,
                    codes=np.array([["1C", "2W"], ["1C", "2W"]]), freq_hz=np.array([[F1, F2], [F1, F2]]),
                    code_m=code, phase_cyc=phase, cnr_dbhz=np.full((1, 2, 2), 45.0), lli=np.zeros((1, 2, 2), np.int8),
                    corrected=np.array([[True, corrected_g02]]), model=np.zeros((1, 2), np.int8),
                    distance_to_master_m=np.array([3000.0]))


def _lock_ms(data: bytes) -> dict[str, float]:
    reader = MessageReader()
    out = {}
    for msg in reader.feed(data):
        if isinstance(msg, MsmMessage):
            obs = msm_to_observables(msg)
            for k, prn in enumerate(obs.sat_ids):
                out[f"G{int(prn):02d}"] = float(np.nanmin(obs.lock_ms[k]))
    return out


def test_the_vrs_is_flagged_non_physical_and_a_correction_switch_restarts_the_lock():
    enc = VrsStreamEncoder()
    enc.add("train", 2001, [-2.2e6, 4.4e6, 4.0e6])
    nav = NavigationData([])
    locks = []
    first = b""
    for k in range(12):
        data = enc.encode(["train"], _epoch(T0 + k, corrected_g02=k < 8), nav)["train"]
        first = first or data
        locks.append(_lock_ms(data))
    arp = [m for _, m in RTCMReader(io.BytesIO(first)) if m is not None and m.identity in ("1005", "1006")]
    assert arp and arp[0].DF141 == 1  # pyrtcm reads a computed (non-physical) reference station
    assert locks[7]["G01"] >= locks[5]["G01"] > 0  # G01 keeps its lock throughout
    assert locks[11]["G01"] > locks[7]["G01"]
    assert locks[8]["G02"] < locks[7]["G02"]  # G02 lost its network corrections at k = 8: lock restarted


def _tiled(ep: VrsEpoch, n: int) -> VrsEpoch:
    """The same epoch for `n` clients."""
    rep = {k: np.repeat(getattr(ep, k), n, axis=0) for k in ("points_ecef_m", "code_m", "phase_cyc", "cnr_dbhz",
                                                            "lli", "corrected", "model", "distance_to_master_m")}
    return VrsEpoch(t_gpst=ep.t_gpst, master=ep.master * n, sats=ep.sats, codes=ep.codes, freq_hz=ep.freq_hz, **rep)


def test_clients_joining_keep_the_others_locks_and_grow_only_the_client_axis():
    enc = VrsStreamEncoder()
    nav = NavigationData([])
    ids = ["first"]
    enc.add("first", 2000, [-2.2e6, 4.4e6, 4.0e6])
    locks = []
    for k in range(8):
        if k >= 2:  # 300 clients join over six epochs: the client axis grows 16 -> 512
            for j in range(50):
                cid = f"T{k}-{j}"
                enc.add(cid, 2001 + len(ids), [-2.2e6, 4.4e6, 4.0e6])
                ids.append(cid)
        out = enc.encode(ids, _tiled(_epoch(T0 + k, corrected_g02=True), len(ids)), nav)
        locks.append(_lock_ms(out["first"]))
        if k >= 2:
            assert _lock_ms(out[ids[-1]])["G01"] == 0.0  # a new client's lock starts at its first epoch
    g01 = [lk["G01"] for lk in locks]
    assert g01[0] == 0.0 and all(b > a for a, b in zip(g01, g01[1:]))  # never restarted by the growth
    # the lock state is (clients x satellite-signals): 301 clients and 4 signals must not take the
    # product of both doublings (2,000 clients once held 2,048 x 8,192 cells, 512 MB)
    rows, keys = enc._lock_t0.shape
    assert len(ids) <= rows <= 2 * len(ids) and keys <= 64
    assert enc._eph_sent.shape[0] <= 2 * len(ids) and enc._eph_sent.shape[1] <= 64
