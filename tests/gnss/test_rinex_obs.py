"""RINEX observations: the real 3.x and 2.11 files read; 3.04 write -> read is exact."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from augnet.gnss import time as gt
from augnet.gnss.rinex.obs import ObsHeader, empty_obs, read_obs, write_obs

OBS3_FILES = [
    ("rinex/static-1m-2024/base.obs", 301, 57),
    ("rinex/static-1m-2024/rover.obs", 301, 58),
    ("rinex/rtk-base-rover-yokohama-2021/base-3034265G.21O", 360, 18),
    ("rinex/rtk-base-rover-yokohama-2021/rover-SEPT265G.21O", 360, 20),
]


def _assert_same(a, b):
    assert np.array_equal(a.times, b.times)
    assert a.sats.tolist() == b.sats.tolist()
    assert np.array_equal(a.flags, b.flags)
    assert np.array_equal(a.clock_offset_s, b.clock_offset_s, equal_nan=True)
    assert set(a.obs) == set(b.obs)
    for k in a.obs:
        assert np.array_equal(a.obs[k], b.obs[k], equal_nan=True), k
        assert np.array_equal(a.lli[k], b.lli[k]), k
        assert np.array_equal(a.ssi[k], b.ssi[k]), k


@pytest.mark.parametrize("name,epochs,sats", OBS3_FILES)
def test_real_rinex3_files(shared_data, name, epochs, sats):
    d = read_obs(shared_data / name)
    assert d.header.version == 3.04
    assert len(d.times) == epochs and len(d.sats) == sats
    assert d.times[0] == d.header.time_of_first_obs
    assert np.all(np.diff(d.times) == 1.0)  # 1 Hz, no gap
    # Every value is either NaN or a plausible observable; each satellite has its system's types.
    for sat_i, sat in enumerate(d.sats):
        types = d.header.obs_types[sat[0]]
        assert any(np.isfinite(d.obs[t][:, sat_i]).any() for t in types)
    code = d.obs["C1C"] if "C1C" in d.obs else d.obs["C1X"]
    ok = np.isfinite(code)
    assert ok.any() and np.all((code[ok] > 1.5e7) & (code[ok] < 4.5e7))


def test_values_match_the_file_text(shared_data):
    d = read_obs(shared_data / "rinex/rtk-base-rover-yokohama-2021/base-3034265G.21O")
    h = d.header
    assert h.receiver_type == "TRIMBLE NetR9" and h.antenna_type == "TRM159900.00    SCIS"
    assert h.approx_position_m == (-3959403.8133, 3385705.8562, 3667525.858)
    assert h.obs_types["G"][:4] == ["C1C", "L1C", "D1C", "S1C"] and len(h.obs_types["G"]) == 16
    assert len(h.obs_types["J"]) == 20
    assert d.times[0] == gt.from_calendar(2021, 9, 22, 6, 30, 0)
    g13 = d.sat_index("G13")
    # "G13  21530120.094   113141646.139       -1980.211          46.200    21530120.688 ..."
    assert d.obs["C1C"][0, g13] == 21530120.094
    assert d.obs["L1C"][0, g13] == 113141646.139
    assert d.obs["D1C"][0, g13] == -1980.211
    assert d.obs["S1C"][0, g13] == 46.2
    assert d.obs["C2W"][0, g13] == 21530120.688
    assert np.isnan(d.obs["C5X"][0, g13])


def test_real_file_write_read_round_trip(shared_data, tmp_path):
    d = read_obs(shared_data / "rinex/rtk-base-rover-yokohama-2021/rover-SEPT265G.21O")
    out = tmp_path / "rover.rnx"
    write_obs(out, d)
    _assert_same(d, read_obs(out))
    assert (d.ssi["C1C"] != 0).any() or np.isfinite(d.obs["S1C"]).any()


def test_synthetic_round_trip_with_flags_lli_ssi_clock_and_gzip(tmp_path):
    rng = np.random.default_rng(7)
    header = ObsHeader(
        marker_name="TRACK-KM12",
        marker_number="0001",
        receiver_type="augnet sim",
        antenna_type="TRM59800.00     NONE",
        approx_position_m=(-2148744.2, 4426641.3, 4044655.9),
        antenna_delta_hen_m=(0.1, 0.0, 0.0),
        obs_types={
            "G": ["C1C", "L1C", "D1C", "S1C", "C2W", "L2W", "C5Q", "L5Q"],
            "E": ["C1C", "L1C", "S1C", "C5Q", "L5Q", "C7Q", "L7Q"],
            "C": ["C2I", "L2I", "S2I", "C6I", "L6I", "C1P", "L1P", "C5P", "L5P"],
        },
        signal_strength_unit="DBHZ",
        interval_s=0.5,
        leap_seconds=18,
    )
    t0 = gt.from_calendar(2026, 3, 1, 12, 0, 0)
    times = t0 + 0.5 * np.arange(20) + 1.25e-4  # an unsteered receiver clock's time tags
    sats = ["C01", "C19", "C59", "E05", "E31", "G02", "G32"]
    d = empty_obs(header, times, sats)
    for k in d.obs:
        kind = k[0]
        scale = {"C": 2.2e7, "L": 1.2e8, "D": 3000.0, "S": 45.0}[kind]
        vals = np.round(rng.uniform(0.1, 1.0, d.obs[k].shape) * scale, 3)
        vals[rng.random(vals.shape) < 0.15] = np.nan  # missing observations
        d.obs[k][:] = vals
        if kind == "L":
            d.lli[k][:] = np.where(np.isnan(vals), 0, rng.integers(0, 8, vals.shape))
        d.ssi[k][:] = np.where(np.isnan(vals), 0, rng.integers(0, 10, vals.shape))
    # Each satellite only holds its own system's types.
    for j, s in enumerate(sats):
        for k in d.obs:
            if k not in header.obs_types[s[0]]:
                d.obs[k][:, j] = np.nan
                d.lli[k][:, j] = 0
                d.ssi[k][:, j] = 0
    d.flags[5] = 1  # power failure
    d.clock_offset_s[:] = np.round(rng.normal(0, 1e-4, len(times)), 12)
    for name in ("sim.rnx", "sim.rnx.gz"):
        out = tmp_path / name
        write_obs(out, d)
        _assert_same(d, read_obs(out))
    text = (tmp_path / "sim.rnx").read_text().splitlines()
    assert text[0].startswith("     3.04           OBSERVATION DATA    M")
    assert any(line.startswith("C    9 C2I L2I S2I") and line.endswith("SYS / # / OBS TYPES ") for line in text)
    first = next(line for line in text if line.endswith("TIME OF FIRST OBS   "))
    assert first.startswith("  2026     3     1    12     0") and first[48:51] == "GPS"
    assert abs(float(first[30:43]) - 1.25e-4) < 2e-7  # GPST seconds hold +-0.12 us (time.py)


def test_bdt_time_system_file_epochs_are_converted_to_gpst(tmp_path):
    header = ObsHeader(obs_types={"C": ["C2I"]}, time_system="BDT")
    t = gt.from_calendar(2026, 3, 1, 12, 0, 14)  # GPST
    d = empty_obs(header, [t], ["C20"])
    d.obs["C2I"][0, 0] = 21_000_000.0
    write_obs(tmp_path / "bdt.rnx", d)
    text = (tmp_path / "bdt.rnx").read_text()
    assert "> 2026 03 01 12 00  0.0000000" in text  # written as BDT = GPST - 14 s
    assert read_obs(tmp_path / "bdt.rnx").times[0] == t


def test_rinex2_files(shared_data):
    folder = shared_data / "rinex" / "nl-network-2021"
    d = read_obs(folder / "delf0010.21o")
    assert d.header.version == 2.11
    assert d.header.obs_types["G"] == ["L1", "L2", "C1", "P2", "P1", "S1", "S2"]
    assert d.times[0] == gt.from_calendar(2021, 1, 1) and np.all(np.diff(d.times) == 30.0)
    assert len(d.times) == 105
    assert {"G07", "R24", "R09"} <= set(d.sats.tolist())
    # the 20 satellites of the first epoch, as listed on its two lines
    assert np.sum(np.isfinite(d.obs["C1"][0])) == 20
    # First epoch, first satellite G07: L1 126298057.858 LLI blank SSI 6, C1 24033720.416.
    g07 = d.sat_index("G07")
    assert d.obs["L1"][0, g07] == 126298057.858 and d.ssi["L1"][0, g07] == 6
    assert d.obs["C1"][0, g07] == 24033720.416 and d.obs["S1"][0, g07] == 40.0
    for name in ("rovn0010.21o", "wsra0010.21o", "zegv0010.21o"):
        o = read_obs(folder / name)
        assert len(o.times) > 0 and np.isfinite(o.obs["C1"]).any()


def test_rinex2_converted_to_rinex3_types_and_written(shared_data, tmp_path):
    from augnet.gnss.rinex.obs import rinex3_type, to_rinex3_types

    assert rinex3_type("G", "P2") == "C2W" and rinex3_type("G", "C1") == "C1C" and rinex3_type("R", "P1") == "C1P"
    assert rinex3_type("G", "C7") is None
    v2 = read_obs(shared_data / "rinex" / "nl-network-2021" / "delf0010.21o")
    v3 = to_rinex3_types(v2)
    assert v3.header.obs_types["G"] == ["L1C", "L2W", "C1C", "C2W", "C1W", "S1C", "S2W"]
    assert v3.header.obs_types["R"] == ["L1C", "L2P", "C1C", "C2P", "C1P", "S1C", "S2P"]
    gps = np.array([s[0] == "G" for s in v2.sats.tolist()])
    assert np.array_equal(v3.obs["C2W"][:, gps], v2.obs["P2"][:, gps], equal_nan=True)
    assert np.all(np.isnan(v3.obs["C2W"][:, ~gps]))
    assert np.array_equal(v3.obs["C2P"][:, ~gps], v2.obs["P2"][:, ~gps], equal_nan=True)
    out = tmp_path / "delf.rnx"
    write_obs(out, v3)
    back = read_obs(out)
    assert back.header.version == 3.04
    _assert_same(v3, back)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.floats(min_value=-999_999_999.999, max_value=9_999_999_999.999, allow_nan=False), min_size=1, max_size=50))
def test_vectorised_f14_3_equals_printf(values):
    from augnet.gnss.rinex.obs import _f14_3

    v = np.array(values)
    ours = [row.tobytes().decode() for row in _f14_3(v).reshape(len(v), 14)]
    for x, text in zip(values, ours):
        expected = f"{x:14.3f}"
        if expected.strip() == "-0.000":  # printf keeps the sign of a value that rounds to zero
            expected = f"{0.0:14.3f}"
        assert text == expected


def test_writer_rejects_values_f14_3_cannot_hold(tmp_path):
    header = ObsHeader(obs_types={"G": ["L1C"]})
    d = empty_obs(header, [gt.from_calendar(2026, 1, 1)], ["G01"])
    d.obs["L1C"][0, 0] = -1_000_000_000.0  # 15 characters with the sign
    with pytest.raises(ValueError, match="G01 L1C"):
        write_obs(tmp_path / "x.rnx", d)
