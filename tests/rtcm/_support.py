"""Helpers shared by the RTCM tests: pyrtcm's view of a frame, and Hypothesis strategies."""

from __future__ import annotations

import numpy as np
from hypothesis import strategies as st
from pyrtcm import RTCMReader

from augnet.gnss.rtcm.fields import FIELDS
from augnet.gnss.rtcm.layouts import LAYOUTS, MSM_MAX_CELLS, Repeat, cell_fields, msm_kind, sat_fields
from augnet.gnss.rtcm.msm import MsmMessage

# pyrtcm attributes that it derives (PRN labels, counts) rather than reads from the bits
_DERIVED_PREFIXES = ("PRN_", "CELLPRN_", "CELLSIG_")
_DERIVED = {"NSat", "NSig", "NCell"}


def pyrtcm_fields(raw_frame: bytes) -> dict[str, object]:
    """pyrtcm's decoded attributes of a framed message (it checks the CRC itself)."""
    msg = RTCMReader.parse(raw_frame)
    return {
        k: v for k, v in vars(msg).items()
        if not k.startswith("_") and k not in _DERIVED and not k.startswith(_DERIVED_PREFIXES)
    }


def assert_same_fields(ours: dict, theirs: dict, context: str = "") -> None:
    assert set(ours) == set(theirs), f"{context}: field names differ: {set(ours) ^ set(theirs)}"
    diff = {k: (ours[k], theirs[k]) for k in ours if ours[k] != theirs[k]}
    assert not diff, f"{context}: values differ (ours, pyrtcm): {dict(list(diff.items())[:8])}"


def raw_in_range(name: str):
    f = FIELDS[name]
    return st.integers(f.raw_min, f.raw_max)


@st.composite
def fixed_message_fields(draw, msg_type: int) -> dict[str, object]:
    """Random valid contents of a fixed-layout message, as pyrtcm-style scaled values."""
    from augnet.gnss.rtcm.fields import to_value

    out: dict[str, object] = {"DF002": msg_type}
    for item in LAYOUTS[msg_type]:
        if isinstance(item, Repeat):
            count = out[item.counter]
            for i in range(count):
                out[f"{item.item}_{i + 1:02d}"] = to_value(FIELDS[item.item], draw(raw_in_range(item.item)))
        elif item == "DF002":
            continue
        elif item in ("DF029", "DF032", "DF227", "DF229", "DF231"):
            out[item] = draw(st.integers(0, 20))  # string lengths: keep messages small
        else:
            out[item] = to_value(FIELDS[item], draw(raw_in_range(item)))
    return out


@st.composite
def msm_messages(draw, msg_type: int, max_sats: int = 32, max_sigs: int = 3) -> MsmMessage:
    """Random valid MSM with 1..max_sats satellites, 1..max_sigs signals, at most 64 cells."""
    system, level = msm_kind(msg_type)
    nsig = draw(st.integers(1, max_sigs))
    nsat = draw(st.integers(1, min(max_sats, MSM_MAX_CELLS // nsig)))
    sat_ids = np.array(sorted(draw(st.sets(st.integers(1, 64), min_size=nsat, max_size=nsat))))
    sig_ids = np.array(sorted(draw(st.sets(st.integers(1, 32), min_size=nsig, max_size=nsig))))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    cell_mask = rng.random((nsat, nsig)) < draw(st.sampled_from([0.5, 0.9, 1.0]))
    ncell = int(cell_mask.sum())

    def rand(df: str, n: int) -> np.ndarray:
        f = FIELDS[df]
        return rng.integers(f.raw_min, f.raw_max, size=n, endpoint=True)

    kw = {}
    for role, df in sat_fields(system, level):
        kw[role] = rand(df, nsat)
    for role, df in cell_fields(level):
        kw[role] = rand(df, ncell)
    head = {name: int(rng.integers(0, 1 << FIELDS[df].width))
            for name, df in (("multiple", "DF393"), ("iods", "DF409"), ("reserved", "DF001_7"),
                             ("clock_steering", "DF411"), ("external_clock", "DF412"),
                             ("smoothing", "DF417"), ("smoothing_interval", "DF418"))}
    return MsmMessage(msg_type=msg_type, station_id=int(rng.integers(0, 4096)), epoch=int(rng.integers(0, 1 << 30)),
                      sat_ids=sat_ids, sig_ids=sig_ids, cell_mask=cell_mask, **kw, **head)
