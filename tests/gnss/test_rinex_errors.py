"""Malformed RINEX: one error type, naming the file and the line; never another exception."""

from __future__ import annotations

import gzip

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from augnet.gnss import time as gt
from augnet.gnss.ephemeris import Ephemeris
from augnet.gnss.rinex import RinexError, read_nav, read_obs
from augnet.gnss.rinex.nav import write_nav
from augnet.gnss.rinex.obs import ObsHeader, empty_obs, write_obs

EPH = Ephemeris(
    system="G", prn=3, week=2300, toe=7200.0, toc=7200.0, af0=1e-4, af1=1e-12, af2=0.0, iode=5,
    crs=1.0, delta_n=4e-9, m0=0.3, cuc=1e-6, e=0.01, cus=1e-6, sqrt_a=5153.6, cic=1e-8, omega0=1.0,
    cis=1e-8, i0=0.95, crc=200.0, omega=0.5, omega_dot=-8e-9, idot=1e-10, tgd=-5e-9,
)


@pytest.fixture
def nav_lines(tmp_path):
    path = tmp_path / "good.nav"
    write_nav(path, [EPH, EPH.replace(system="E", prn=4, data_sources=517), EPH.replace(system="C", prn=7)])
    return path.read_text().splitlines()


@pytest.fixture
def obs_lines(tmp_path):
    header = ObsHeader(obs_types={"G": ["C1C", "L1C", "S1C"], "E": ["C1C", "L1C"]}, marker_name="X")
    t0 = gt.from_calendar(2026, 1, 2, 3, 4, 5)
    d = empty_obs(header, t0 + np.arange(3.0), ["E02", "G05", "G07"])
    for k, v in (("C1C", 2.2e7), ("L1C", 1.1e8), ("S1C", 44.0)):
        d.obs[k][:] = v
    path = tmp_path / "good.obs"
    write_obs(path, d)
    return path.read_text().splitlines()


def _write(tmp_path, name, lines):
    p = tmp_path / name
    p.write_text("\n".join(lines) + "\n")
    return p


def _expect(path, line_no, words, reader):
    with pytest.raises(RinexError) as info:
        reader(path)
    err = info.value
    assert err.path == str(path)
    assert err.line_no == line_no
    assert str(err).startswith(f"{path}:{line_no}: ")
    for w in words:
        assert w in str(err)


def _header_end(lines):
    return next(i for i, line in enumerate(lines) if "END OF HEADER" in line)


def test_valid_fixtures_read(tmp_path, nav_lines, obs_lines):
    assert len(read_nav(_write(tmp_path, "a.nav", nav_lines)).ephemerides) == 3
    assert read_obs(_write(tmp_path, "a.obs", obs_lines)).obs["C1C"].shape == (3, 3)


def test_nav_orbit_line_missing(tmp_path, nav_lines):
    h = _header_end(nav_lines)
    lines = nav_lines[: h + 1 + 5] + nav_lines[h + 1 + 6 :]  # drop orbit line 5 of the first record
    _expect(_write(tmp_path, "short.nav", lines), h + 1 + 7, ["G03", "6 orbit lines, expected 7"], read_nav)


def test_nav_field_not_a_number(tmp_path, nav_lines):
    h = _header_end(nav_lines)
    k = h + 1 + 8 + 2  # second record (E04), orbit line 2
    lines = list(nav_lines)
    lines[k] = lines[k][:4] + "     1.0x0000E+00  " + lines[k][23:]
    _expect(_write(tmp_path, "nan.nav", lines), k + 1, ["field 1", "not a number"], read_nav)


def test_nav_bad_epoch_and_unknown_system(tmp_path, nav_lines):
    h = _header_end(nav_lines)
    lines = list(nav_lines)
    lines[h + 1] = lines[h + 1][:9] + "13" + lines[h + 1][11:]  # month 13
    _expect(_write(tmp_path, "month.nav", lines), h + 2, ["month"], read_nav)
    lines = list(nav_lines)
    lines[h + 9] = "X" + lines[h + 9][1:]
    _expect(_write(tmp_path, "sys.nav", lines), h + 10, ["unknown satellite system"], read_nav)


def test_nav_header_problems(tmp_path, nav_lines, obs_lines):
    h = _header_end(nav_lines)
    lines = nav_lines[:h] + nav_lines[h + 1 :]
    with pytest.raises(RinexError) as info:
        read_nav(_write(tmp_path, "nohdr.nav", lines))
    assert "nohdr.nav:" in str(info.value)
    _expect(_write(tmp_path, "obs-as-nav.nav", obs_lines), 1, ["not a navigation file"], read_nav)
    _expect(_write(tmp_path, "empty.nav", []), 1, ["first line"], read_nav)


def test_corrupt_gzip(tmp_path, nav_lines):
    p = tmp_path / "bad.nav.gz"
    p.write_bytes(gzip.compress("\n".join(nav_lines).encode())[:-30])
    with pytest.raises(RinexError, match="bad.nav.gz"):
        read_nav(p)


def test_obs_satellite_count_wrong(tmp_path, obs_lines):
    h = _header_end(obs_lines)
    lines = list(obs_lines)
    lines[h + 1] = lines[h + 1][:32] + "  4" + lines[h + 1][35:]  # announces 4, has 3
    # The 4th "satellite line" is the next epoch line.
    _expect(_write(tmp_path, "count.obs", lines), h + 6, ["bad satellite id", "announces 4"], read_obs)
    # Last epoch announcing more satellites than the file holds.
    lines = list(obs_lines)
    last = max(i for i, line in enumerate(lines) if line.startswith(">"))
    lines[last] = lines[last][:32] + "  9" + lines[last][35:]
    _expect(_write(tmp_path, "eof.obs", lines), len(lines), ["announces 9"], read_obs)


def test_obs_bad_value_and_lli(tmp_path, obs_lines):
    h = _header_end(obs_lines)
    lines = list(obs_lines)
    k = h + 3  # second satellite line of the first epoch
    lines[k] = lines[k][:3] + "  22000000.0x0" + lines[k][17:]
    _expect(_write(tmp_path, "val.obs", lines), k + 1, ["observation 1", "not a number"], read_obs)
    lines = list(obs_lines)
    lines[k] = lines[k][:17] + "Z" + lines[k][18:]
    _expect(_write(tmp_path, "lli.obs", lines), k + 1, ["bad LLI"], read_obs)


def test_obs_structure_errors(tmp_path, obs_lines):
    h = _header_end(obs_lines)
    lines = list(obs_lines)
    lines[h + 1] = " " + lines[h + 1][1:]  # epoch line lost its '>'
    _expect(_write(tmp_path, "gt.obs", lines), h + 2, ["epoch line"], read_obs)
    lines = list(obs_lines)
    lines[h + 1] = lines[h + 1][:7] + "xx" + lines[h + 1][9:]
    _expect(_write(tmp_path, "time.obs", lines), h + 2, ["bad epoch time"], read_obs)
    sys_line = next(i for i, line in enumerate(obs_lines) if line.startswith("G    3"))
    lines = list(obs_lines)
    lines[sys_line] = "G    4" + lines[sys_line][6:]
    _expect(_write(tmp_path, "types.obs", lines), sys_line + 1, ["fewer types than announced"], read_obs)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_random_corruption_never_escapes_as_another_error(tmp_path, nav_lines, obs_lines, data):
    """Any byte changed, line dropped or file cut: the reader returns or raises RinexError."""
    for lines, reader, name in ((nav_lines, read_nav, "f.nav"), (obs_lines, read_obs, "f.obs")):
        text = bytearray("\n".join(lines).encode())
        op = data.draw(st.sampled_from(["byte", "drop", "cut"]))
        if op == "byte":
            pos = data.draw(st.integers(0, len(text) - 1))
            text[pos] = data.draw(st.integers(0, 255))
        elif op == "drop":
            k = data.draw(st.integers(0, len(lines) - 1))
            text = bytearray("\n".join(lines[:k] + lines[k + 1 :]).encode())
        else:
            text = text[: data.draw(st.integers(0, len(text)))]
        p = tmp_path / name
        p.write_bytes(bytes(text))
        try:
            reader(p)
        except RinexError as exc:
            assert str(exc).startswith(str(p))
