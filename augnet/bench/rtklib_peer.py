"""RTKLIB's own RTCM 3 MSM7 encoder/decoder as a benchmark peer (issue 17), through the pyrtklib binding
(PyPI `pyrtklib`, RTKLIB 2.4.3 compiled as a pybind11 module; installed with the `test` extra by `make venv`). Only RTKLIB's public
API is called (init_rtcm, gen_rtcm3, input_rtcm3); no RTKLIB code lives in this repository.

Figures include the binding's per-call Python overhead (one gen_rtcm3 call per message, as a caster would
call it), which is stated wherever they are printed."""

from __future__ import annotations

import numpy as np

MSG_GPS_MSM7 = 1077
GPS_WEEK = 2300  # any week: MSM carries the time of week only; both sides agree on it
# RTKLIB signal code per our MSM signal id for GPS (RTCM 10403.3 table 3.5-91: 2 = 1C, 10 = 2W)
_GPS_CODES = {2: "CODE_L1C", 10: "CODE_L2W"}


def load():
    """The pyrtklib module, or (None, reason) when it is not installed: the bench states the reason."""
    try:
        import pyrtklib
    except ImportError as e:  # not silently skipped: callers print this
        return None, f"absent: pyrtklib not installed ({e}); `make venv` installs it (test extra)"
    return pyrtklib, "pyrtklib " + getattr(pyrtklib, "__version__", "installed")


class RtklibMsm7:
    """Holds one rtcm_t and, per receiver, an obsd_t array filled from our observables."""

    def __init__(self, p, sat_ids, sig_ids, pr, cp, dop, cnr, tow_ms: int):
        self.p = p
        self.rtcm = p.rtcm_t()
        p.init_rtcm(self.rtcm)
        self.time = p.gpst2time(GPS_WEEK, tow_ms / 1e3)
        self.rtcm.time = self.time
        codes = [getattr(p, _GPS_CODES[int(s)]) for s in sig_ids]
        pr, cp, dop, cnr = (np.asarray(a).reshape(-1, len(sat_ids), len(sig_ids)) for a in (pr, cp, dop, cnr))
        self.arrays = []
        for rx in range(pr.shape[0]):
            arr = p.Arr1Dobsd_t(len(sat_ids))
            for i, prn in enumerate(sat_ids):
                d = arr[i]
                d.time, d.sat, d.rcv = self.time, p.satno(p.SYS_GPS, int(prn)), 0
                for j, code in enumerate(codes):
                    d.P[j], d.L[j], d.D[j] = float(pr[rx, i, j]), float(cp[rx, i, j]), float(dop[rx, i, j])
                    d.code[j], d.SNR[j] = code, int(round(float(cnr[rx, i, j]) / p.SNR_UNIT))
                arr[i] = d
            self.arrays.append(arr)
        self.n = len(sat_ids)
        self.use(0)

    def use(self, rx: int, station_id: int = 0) -> None:
        self.rtcm.obs.data, self.rtcm.obs.n, self.rtcm.obs.nmax = self.arrays[rx], self.n, self.n
        self.rtcm.staid = station_id

    def encode(self) -> int:
        """One framed MSM7 into rtcm.buff; returns its length in bytes."""
        self.p.gen_rtcm3(self.rtcm, MSG_GPS_MSM7, 0, 0)
        return self.rtcm.nbyte

    def frame(self) -> bytes:
        self.encode()
        return bytes(int(self.rtcm.buff[i]) for i in range(self.rtcm.nbyte))

    def encode_batch(self, station_ids) -> int:
        """One MSM7 per receiver, as a caster loop over receivers would call RTKLIB; total bytes."""
        total = 0
        for rx, sid in enumerate(station_ids):
            self.use(rx, int(sid))
            total += self.encode()
        return total


def decode_with_rtklib(p, frame: bytes, tow_ms: int) -> dict[tuple[int, int], tuple[float, float, float, float]]:
    """RTKLIB's input_rtcm3 on one frame -> {(prn, code): (P m, L cycles, D Hz, SNR dB-Hz)}."""
    r = p.rtcm_t()
    p.init_rtcm(r)
    r.time = p.gpst2time(GPS_WEEK, tow_ms / 1e3)
    status = 0
    for b in frame:
        status = p.input_rtcm3(r, int(b))
    if status != 1:
        raise ValueError(f"RTKLIB input_rtcm3 did not return observations (status {status})")
    out = {}
    for i in range(r.obs.n):
        d = r.obs.data[i]
        for j in range(3):  # NFREQ + NEXOBS slots of this build; empty ones have code 0
            if d.code[j]:
                out[(int(d.sat), int(d.code[j]))] = (d.P[j], d.L[j], d.D[j], d.SNR[j] * p.SNR_UNIT)
    return out
