"""MSM <-> observables: pseudorange [m], carrier phase [cycles], Doppler [Hz], CNR [dB-Hz], lock time.

Arrays are (nsat, nsig) with NaN where a cell is absent or its field carries the "invalid" marker;
the conversion to MSM fields also works with leading axes (nrx, nsat, nsig), which is what the batch
encoder uses. Wavelengths come from ``augnet.gnss.signals`` by (system, MSM signal id).

Field arithmetic (RTCM 10403.3 section 3.5.12.7, DF397-DF408):
  rough range   = DF397 + DF398 * 2^-10                        [ms of light travel]
  pseudorange   = (rough + fine_pr * 2^-24 | 2^-29) * c/1000  [m]   (MSM4 | MSM7)
  phase range   = (rough + fine_ph * 2^-29 | 2^-31) * c/1000  [m]; cycles = phase range / lambda
  range rate    = DF399 + DF404 * 0.0001                       [m/s]; Doppler = -rate / lambda
The sums in milliseconds are exact in binary floating point (dyadic, < 2^53), so decoding rounds once.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from augnet.gnss.constants import SPEED_OF_LIGHT_M_S
from augnet.gnss.rtcm.errors import EncodeError
from augnet.gnss.rtcm.fields import FIELDS
from augnet.gnss.rtcm.layouts import MSM_MAX_CELLS, msm_type
from augnet.gnss.rtcm.msm import INVALID, INVALID_ROUGH_MS, MsmMessage
from augnet.gnss.signals import by_msm

RANGE_MS_M = SPEED_OF_LIGHT_M_S * 1e-3  # metres of light travel per millisecond (RTCM ranges are in ms)
ROUGH_MOD_STEPS_PER_MS = 1024  # DF398 resolution 2^-10 ms
MAX_ROUGH_MS = 254  # DF397: 0..254 ms, 255 marks an invalid rough range
FINE_RATE_M_S = 0.0001  # DF404 resolution

# Resolution of the fine fields per MSM level, as a power of two of a millisecond (exponent)
_FINE_PR_EXP = {4: 24, 5: 24, 6: 29, 7: 29}  # DF400 2^-24 ms, DF405 2^-29 ms
_FINE_PH_EXP = {4: 29, 5: 29, 6: 31, 7: 31}  # DF401 2^-29 ms, DF406 2^-31 ms
_CNR_STEP = {4: 1.0, 5: 1.0, 6: 2.0**-4, 7: 2.0**-4}  # DF403 1 dB-Hz, DF408 2^-4 dB-Hz
_HAS_RATE = {4: False, 5: True, 6: False, 7: True}
_EXTENDED = {4: False, 5: False, 6: True, 7: True}  # DF405-DF408 rather than DF400-DF403

# Lock time indicator DF407 (RTCM 10403.3 Table 3.5-75): indicator i < 64 means i ms; above, segment
# k = 1..21 covers i in [32(k+1), 32(k+1)+31] with step 2^k ms starting at 32 * 2^k ms; 704 means
# at least 2^26 ms; 705..1023 are reserved.
DF407_MAX_INDICATOR = 704
DF407_MAX_LOCK_MS = 1 << 26
# DF402 (Table 3.5-74): 0 means < 32 ms; i = 1..15 means at least 2^(i+4) ms.
DF402_MAX_INDICATOR = 15


def lock_indicator_df402(lock_ms) -> np.ndarray:
    """MSM4/5 lock time indicator from the time the phase has been tracked [ms] (NaN -> 0)."""
    t = np.asarray(lock_ms, dtype=np.float64)
    t = np.where(t > 0.0, t, 0.0)  # NaN and negative -> 0
    _, e = np.frexp(t)  # t = m * 2^e with 0.5 <= m < 1, so floor(log2 t) = e - 1
    return np.clip(e - 1 - 4, 0, DF402_MAX_INDICATOR).astype(np.int64) * (t >= 32)


def lock_time_df402(indicator) -> np.ndarray:
    """Minimum lock time [ms] an MSM4/5 indicator guarantees."""
    i = np.asarray(indicator, dtype=np.int64)
    return np.where(i == 0, 0.0, np.ldexp(1.0, i + 4))


def lock_indicator_df407(lock_ms) -> np.ndarray:
    """MSM6/7 lock time indicator from the time the phase has been tracked [ms] (NaN -> 0)."""
    t = np.asarray(lock_ms, dtype=np.float64)
    t = np.where(t > 0.0, np.minimum(t, DF407_MAX_LOCK_MS), 0.0).astype(np.int64)  # NaN -> 0; floor
    _, bitlen = np.frexp(t.astype(np.float64))  # bit length of t (exact: t < 2^53)
    k = np.maximum(bitlen - 6, 0)
    return np.minimum((t >> k) + 32 * k, DF407_MAX_INDICATOR)


def lock_time_df407(indicator) -> np.ndarray:
    """Minimum lock time [ms] an MSM6/7 indicator guarantees (NaN for reserved indicators)."""
    i = np.asarray(indicator, dtype=np.int64)
    k = np.maximum(i // 32 - 1, 0)
    t = ((i - 32 * k) << k).astype(np.float64)
    return np.where(i > DF407_MAX_INDICATOR, np.nan, t)


@dataclass(eq=False)
class Observables:
    """Observables of one system: (nsat, nsig) arrays (or (..., nsat, nsig)), NaN where absent."""

    system: str
    sat_ids: np.ndarray  # (nsat,) satellite ids (PRN for GPS/Galileo/BDS)
    sig_ids: np.ndarray  # (nsig,) MSM signal ids
    pseudorange_m: np.ndarray
    phase_cycles: np.ndarray
    doppler_hz: np.ndarray
    cnr_dbhz: np.ndarray
    lock_ms: np.ndarray  # minimum continuous tracking time the indicator guarantees
    half_cycle: np.ndarray  # bool: half-cycle ambiguity unresolved

    @property
    def wavelengths_m(self) -> np.ndarray:
        return wavelengths(self.system, self.sig_ids)

    @property
    def rinex_codes(self) -> list[str]:
        return [by_msm(self.system, int(s)).rinex_code for s in self.sig_ids]


def wavelengths(system: str, sig_ids) -> np.ndarray:
    """Carrier wavelength [m] per MSM signal id, from the signals table."""
    return _wavelengths(system, tuple(np.asarray(sig_ids).ravel().tolist()))


@lru_cache(maxsize=4096)
def _wavelengths(system: str, sig_ids: tuple[int, ...]) -> np.ndarray:
    lam = np.array([by_msm(system, int(s)).wavelength_m for s in sig_ids], dtype=np.float64)
    lam.setflags(write=False)  # shared between callers
    return lam


def msm_to_observables(msg: MsmMessage) -> Observables:
    """Full observables from a decoded MSM (NaN where no cell or an invalid marker)."""
    level = msg.level
    nsat, nsig = msg.nsat, msg.nsig
    lam = wavelengths(msg.system, msg.sig_ids)
    si, gi = np.nonzero(msg.cell_mask)
    rough_ms = np.asarray(msg.rough_ms)
    rough = np.where(rough_ms == INVALID_ROUGH_MS, np.nan,
                     rough_ms + np.asarray(msg.rough_mod) * (1.0 / ROUGH_MOD_STEPS_PER_MS))[si]
    ext = _EXTENDED[level]
    pr_df, ph_df = ("DF405", "DF406") if ext else ("DF400", "DF401")

    def cells(values: np.ndarray) -> np.ndarray:
        out = np.full((nsat, nsig), np.nan)
        out[si, gi] = values
        return out

    fpr = np.asarray(msg.fine_pr)
    fph = np.asarray(msg.fine_ph)
    pr = np.where(fpr == INVALID[pr_df], np.nan, rough + np.ldexp(fpr.astype(np.float64), -_FINE_PR_EXP[level]))
    ph = np.where(fph == INVALID[ph_df], np.nan, rough + np.ldexp(fph.astype(np.float64), -_FINE_PH_EXP[level]))
    pseudorange = cells(pr * RANGE_MS_M)
    phase = cells(ph * RANGE_MS_M / lam[gi])
    if _HAS_RATE[level]:
        rr = np.asarray(msg.rough_rate)
        frr = np.asarray(msg.fine_rate)
        rough_rate = np.where(rr == INVALID["DF399"], np.nan, rr.astype(np.float64))[si]
        rate = np.where(frr == INVALID["DF404"], np.nan, rough_rate + frr * FINE_RATE_M_S)
        doppler = cells(-rate / lam[gi])
    else:
        doppler = np.full((nsat, nsig), np.nan)
    cnr_raw = np.asarray(msg.cnr)
    cnr = cells(np.where(cnr_raw == 0, np.nan, cnr_raw * _CNR_STEP[level]))
    lock = cells(lock_time_df407(msg.lock) if ext else lock_time_df402(msg.lock))
    half = np.zeros((nsat, nsig), dtype=bool)
    half[si, gi] = np.asarray(msg.half_cycle) != 0
    return Observables(msg.system, np.asarray(msg.sat_ids), np.asarray(msg.sig_ids), pseudorange, phase,
                       doppler, cnr, lock, half)


def _first_finite(a: np.ndarray) -> np.ndarray:
    """Along the last (signal) axis, the first finite value (NaN when none).

    A loop over the few signals (<= 32, usually 2-3) of whole-array selects: cheaper than argmax +
    take_along_axis for the batch encoder's (nrx, nsat, nsig) arrays.
    """
    if a.shape[-1] == 0:
        return np.full(a.shape[:-1], np.nan)
    out = a[..., -1].copy()
    for j in range(a.shape[-1] - 2, -1, -1):
        col = a[..., j]
        np.copyto(out, col, where=np.isfinite(col))
    return out


def _fit(raw: np.ndarray, df: str) -> np.ndarray:
    """Round to the field's integer; NaN or out of range becomes the field's invalid marker."""
    invalid = INVALID[df]
    r = np.rint(raw)
    ok = (r > invalid) & (r <= FIELDS[df].raw_max)  # False for NaN
    return np.where(ok, r, invalid).astype(np.int64)


def phase_offset_cycles(pseudorange_m, phase_cycles, wavelength_m) -> np.ndarray:
    """Whole cycles to subtract from a phase so that its range lies within half a cycle of the pseudorange.

    MSM carries the phase range as an offset of at most +-1171 m (2^-8 ms) from the rough range,
    so a phase with an arbitrary integer ambiguity does not fit and would be sent as invalid. A
    sender picks this offset when it starts tracking a cell and keeps it for the whole lock (a new
    offset is a cycle slip for the receiver: reset the lock time with it). NaN gives 0.
    """
    lam = np.asarray(wavelength_m, dtype=np.float64)
    d = (np.asarray(phase_cycles, dtype=np.float64) * lam - np.asarray(pseudorange_m, dtype=np.float64)) / lam
    return np.where(np.isfinite(d), np.rint(d), 0.0).astype(np.int64)


def cell_presence(pseudorange_m, phase_cycles) -> np.ndarray:
    """A cell is sent when it has a pseudorange or a phase."""
    return np.isfinite(pseudorange_m) | np.isfinite(phase_cycles)


def observables_to_fields(level: int, wavelengths_m: np.ndarray, pseudorange_m, phase_cycles, doppler_hz=None,
                          cnr_dbhz=None, lock_ms=None, half_cycle=None) -> dict[str, np.ndarray]:
    """Raw MSM field integers on the full grid: satellite roles (..., nsat), cell roles (..., nsat, nsig).

    Rough range per satellite: the first finite pseudorange (else the first phase range), rounded to
    2^-10 ms; fine values are the remainders, rounded to the field's resolution. A value that does not
    fit its field (e.g. a phase more than 1171 m from the rough range: its integer ambiguity is the
    caller's to choose) is sent as the field's "invalid" marker, as the standard prescribes.
    """
    pr = np.asarray(pseudorange_m, dtype=np.float64)
    lam = np.asarray(wavelengths_m, dtype=np.float64)
    php = np.asarray(phase_cycles, dtype=np.float64) * lam  # phase range [m]
    pr_ms = pr / RANGE_MS_M
    ph_ms = php / RANGE_MS_M
    ref = _first_finite(pr_ms)
    no_pr = ~np.isfinite(ref)
    if no_pr.any():  # phase-only satellites: take the rough range from the phase range
        ref = np.where(no_pr, _first_finite(ph_ms), ref)
    units = np.rint(np.where(np.isnan(ref), -1.0, ref) * ROUGH_MOD_STEPS_PER_MS)
    rough_ok = np.isfinite(ref) & (units >= 0) & (units < (MAX_ROUGH_MS + 1) * ROUGH_MOD_STEPS_PER_MS)
    units = np.where(rough_ok, units, 0.0).astype(np.int64)
    rough_ms = np.where(rough_ok, units >> 10, INVALID_ROUGH_MS)
    rough_mod = units & (ROUGH_MOD_STEPS_PER_MS - 1)
    rough = np.where(rough_ok, units * (1.0 / ROUGH_MOD_STEPS_PER_MS), np.nan)[..., None]
    ext = _EXTENDED[level]
    pr_df, ph_df = ("DF405", "DF406") if ext else ("DF400", "DF401")
    out = {
        "rough_ms": rough_ms,
        "rough_mod": rough_mod,
        # multiplying by a power of two is exact, and cheaper than np.ldexp
        "fine_pr": _fit((pr_ms - rough) * 2.0 ** _FINE_PR_EXP[level], pr_df),
        "fine_ph": _fit((ph_ms - rough) * 2.0 ** _FINE_PH_EXP[level], ph_df),
    }
    shape = pr.shape
    if _HAS_RATE[level]:
        if doppler_hz is None:
            rate = np.full(shape, np.nan)
        else:
            rate = -np.asarray(doppler_hz, dtype=np.float64) * lam
        ref_rate = _first_finite(rate)
        rough_rate = _fit(ref_rate, "DF399")
        rr = np.where(rough_rate == INVALID["DF399"], np.nan, rough_rate.astype(np.float64))[..., None]
        out["rough_rate"] = rough_rate
        out["ext_info"] = np.zeros(rough_ms.shape, dtype=np.int64)
        out["fine_rate"] = _fit((rate - rr) / FINE_RATE_M_S, "DF404")
    cnr_field = FIELDS["DF408" if ext else "DF403"]
    if cnr_dbhz is None:
        out["cnr"] = np.zeros(shape, dtype=np.int64)
    else:
        c = np.asarray(cnr_dbhz, dtype=np.float64)
        c = np.rint(np.where(np.isnan(c), 0.0, c) / _CNR_STEP[level])
        out["cnr"] = np.clip(c, 0, cnr_field.raw_max).astype(np.int64)
    lock = np.zeros(shape) if lock_ms is None else np.broadcast_to(np.asarray(lock_ms, dtype=np.float64), shape)
    out["lock"] = lock_indicator_df407(lock) if ext else lock_indicator_df402(lock)
    half = np.zeros(shape, dtype=bool) if half_cycle is None else np.broadcast_to(half_cycle, shape)
    out["half_cycle"] = np.asarray(half, dtype=bool).astype(np.int64)
    return out


SAT_ROLES = ("rough_ms", "rough_mod", "rough_rate", "ext_info")


def observables_to_msm(obs: Observables, level: int, station_id: int, epoch: int, **header) -> MsmMessage:
    """One MSM (level 4..7) from (nsat, nsig) observables; satellites and signals without any cell are
    left out of the masks. ``header`` sets DF393 ``multiple``, ``iods``, ``clock_steering`` ..."""
    pr = np.asarray(obs.pseudorange_m, dtype=np.float64)
    if pr.ndim != 2:
        raise EncodeError(f"observables_to_msm takes (nsat, nsig) arrays, got shape {pr.shape}")
    fields = observables_to_fields(level, obs.wavelengths_m, pr, obs.phase_cycles, obs.doppler_hz, obs.cnr_dbhz,
                                   obs.lock_ms, obs.half_cycle)
    present = cell_presence(pr, obs.phase_cycles)
    return _compact(obs.system, level, np.asarray(obs.sat_ids), np.asarray(obs.sig_ids), present, fields,
                    station_id, epoch, header)


def _compact(system, level, sat_ids, sig_ids, present, fields, station_id, epoch, header) -> MsmMessage:
    keep_sat = present.any(axis=1)
    keep_sig = present.any(axis=0)
    mask = present[np.ix_(keep_sat, keep_sig)]
    kw = {}
    for role, arr in fields.items():
        if role in SAT_ROLES:
            kw[role] = arr[keep_sat]
        else:
            kw[role] = arr[np.ix_(keep_sat, keep_sig)][mask]
    return MsmMessage(msg_type=msm_type(system, level), station_id=station_id, epoch=epoch,
                      sat_ids=sat_ids[keep_sat], sig_ids=sig_ids[keep_sig], cell_mask=mask, **kw, **header)


def observables_to_msm_list(obs: Observables, level: int, station_id: int, epoch: int, **header) -> list[MsmMessage]:
    """As ``observables_to_msm``, split over several messages when the cells exceed the MSM limit of 64:
    satellites are cut into groups of at most 64 // Nsig; DF393 (multiple message bit) is 1 on all but
    the last message of the epoch."""
    pr = np.asarray(obs.pseudorange_m, dtype=np.float64)
    present = cell_presence(pr, obs.phase_cycles)
    sat_rows = np.flatnonzero(present.any(axis=1))
    nsig = max(int(present.any(axis=0).sum()), 1)
    per_msg = max(MSM_MAX_CELLS // nsig, 1)
    groups = [sat_rows[i : i + per_msg] for i in range(0, len(sat_rows), per_msg)] or [sat_rows]
    fields = observables_to_fields(level, obs.wavelengths_m, pr, obs.phase_cycles, obs.doppler_hz, obs.cnr_dbhz,
                                   obs.lock_ms, obs.half_cycle)
    out = []
    multiple_last = header.pop("multiple", 0)
    for n, rows in enumerate(groups):
        sub = {role: arr[rows] for role, arr in fields.items()}
        last = n == len(groups) - 1
        out.append(_compact(obs.system, level, np.asarray(obs.sat_ids)[rows], np.asarray(obs.sig_ids),
                            present[rows], sub, station_id, epoch,
                            {**header, "multiple": multiple_last if last else 1}))
    return out
