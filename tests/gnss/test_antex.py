"""ANTEX reader and receiver antenna phase-centre corrections (augnet.gnss.antex)."""

from __future__ import annotations

import gzip
import math
import warnings

import numpy as np
import pytest

from augnet.gnss.antex import AntexError, antennas_for, read_antex, split_antenna_type

# A tiny ANTEX 1.4 file: one azimuth-independent antenna (zenith 0-90 by 30), one azimuth-dependent (DAZI
# 180), one satellite. Columns as the format says: labels from column 61.
HEADER = [
    f"{'     1.4            M':<60}ANTEX VERSION / SYST",
    f"{'A':<60}PCV TYPE / REFANT",
    f"{'':<60}END OF HEADER",
]


def _antenna(type_radome: str, serial: str, dazi: float, zen: tuple[float, float, float], freqs: dict) -> list[str]:
    out = [f"{'':<60}START OF ANTENNA", f"{type_radome:<20}{serial:<40}TYPE / SERIAL NO",
           f"{'ROBOT               test                     1    01-JAN-10':<60}METH / BY / # / DATE",
           f"{dazi:8.1f}{'':<52}DAZI",
           f"  {zen[0]:6.1f}{zen[1]:6.1f}{zen[2]:6.1f}{'':<42}ZEN1 / ZEN2 / DZEN",
           f"{len(freqs):6d}{'':<54}# OF FREQUENCIES"]
    for code, (neu, noazi, rows) in freqs.items():
        out.append(f"   {code:<57}START OF FREQUENCY")
        out.append(f"{neu[0]:10.2f}{neu[1]:10.2f}{neu[2]:10.2f}{'':<30}NORTH / EAST / UP")
        out.append("   NOAZI" + "".join(f"{v:8.2f}" for v in noazi))
        for az, vals in rows:
            out.append(f"{az:8.1f}" + "".join(f"{v:8.2f}" for v in vals))
        out.append(f"   {code:<57}END OF FREQUENCY")
    out.append(f"{'':<60}END OF ANTENNA")
    return out


def tiny_antex() -> list[str]:
    lines = list(HEADER)
    lines += _antenna("TEST1           NONE", "", 0.0, (0.0, 90.0, 30.0), {
        "G01": ((1.0, 2.0, 50.0), (0.0, -2.0, -4.0, 6.0), []),
        "G02": ((0.0, 0.0, 60.0), (0.0, 1.0, 2.0, 3.0), []),
    })
    lines += _antenna("TEST2           NONE", "", 180.0, (0.0, 90.0, 45.0), {
        "G01": ((0.0, 0.0, 10.0), (0.0, 0.0, 0.0),
                [(0.0, (0.0, 2.0, 4.0)), (180.0, (0.0, 4.0, 8.0)), (360.0, (0.0, 2.0, 4.0))]),
    })
    lines += _antenna("BLOCK IIR-M", "G05                 G050", 0.0, (0.0, 17.0, 1.0), {
        "G01": ((0.0, 0.0, 800.0), (0.0,) * 18, []),
    })
    return lines


@pytest.fixture
def tiny(tmp_path):
    p = tmp_path / "tiny.atx"
    p.write_text("\n".join(tiny_antex()) + "\n")
    return read_antex(p)


def test_tiny_offsets_and_variations(tiny):
    ant = tiny.receiver("TEST1           NONE")
    assert ant.frequencies["G01"].pco_neu_m == pytest.approx([1e-3, 2e-3, 50e-3])
    f1 = ant.frequencies["G01"]
    assert f1.zenith_deg.tolist() == [0.0, 30.0, 60.0, 90.0]
    # linear in zenith between the grid's nodes
    assert f1.pcv(15.0) == pytest.approx(-1e-3)
    assert f1.pcv(75.0) == pytest.approx(1e-3)
    assert "G05" in tiny.satellites and "G05" not in {k[:3] for k in tiny.receivers}


def test_correction_is_pco_along_the_line_of_sight_minus_pcv(tiny):
    ant = tiny.receiver("TEST1", "NONE")
    el = np.radians([90.0, 60.0, 30.0])  # zenith 0, 30, 60
    az = np.radians([0.0, 90.0, 0.0])
    corr = ant.correction_m(az, el, ["G01", "G02", "G03"], [["1C", "2W"]] * 3)
    pco1 = np.array([1.0, 2.0, 50.0]) * 1e-3
    e = np.stack([np.cos(az) * np.cos(el), np.sin(az) * np.cos(el), np.sin(el)], axis=1)  # north, east, up
    assert corr[:, 0] == pytest.approx(e @ pco1 - np.array([0.0, -2.0, -4.0]) * 1e-3)
    assert corr[:, 1] == pytest.approx(e @ np.array([0.0, 0.0, 0.06]) - np.array([0.0, 1.0, 2.0]) * 1e-3)
    # at the zenith the correction is the up offset: the phase centre is nearer the satellite than the ARP
    assert corr[0, 0] == pytest.approx(0.050)


def test_azimuth_dependent_pcv_is_bilinear(tiny):
    f = tiny.receiver("TEST2").frequencies["G01"]
    assert f.pcv(45.0, 0.0) == pytest.approx(2e-3)
    assert f.pcv(45.0, 180.0) == pytest.approx(4e-3)
    assert f.pcv(45.0, 90.0) == pytest.approx(3e-3)
    assert f.pcv(22.5, 90.0) == pytest.approx(1.5e-3)
    assert f.pcv(45.0, 360.0 + 90.0) == pytest.approx(3e-3)  # azimuths wrap
    assert f.pcv(45.0) == pytest.approx(0.0)  # without an azimuth: NOAZI
    got = f.pcv(np.array([45.0, np.nan, 45.0]), np.array([90.0, 10.0, np.nan]))  # no position: NaN
    assert got[0] == pytest.approx(3e-3) and np.isnan(got[1:]).all()
    corr = tiny.receiver("TEST2").correction_m([np.nan, 0.0], [np.nan, 1.0], ["G01", "G02"], [["1C"], ["1C"]])
    assert np.isnan(corr[0, 0]) and np.isfinite(corr[1, 0])


def test_missing_frequency_takes_gps_of_the_band_and_says_so(tiny):
    ant = tiny.receiver("TEST1")
    corr = ant.correction_m([0.0], [math.pi / 2], ["E11"], [["1C", "5Q"]])
    assert corr[0, 0] == pytest.approx(0.050)  # E01 -> G01
    assert corr[0, 1] == pytest.approx(0.060)  # E05 -> G02 (no G05)
    assert ant.stand_ins(["E11"], [["1C", "5Q"]]) == ["E01", "E05"]
    assert ant.correction_m([0.0], [math.pi / 2], ["G01"], [["1C", ""]])[0, 1] == 0.0  # nothing observed


def test_radome_falls_back_to_none_with_a_flag(tiny):
    with pytest.warns(UserWarning, match="radome NONE"):
        ant = tiny.receiver("TEST1           SCIS")
    assert ant.radome_fallback and ant.radome == "SCIS"
    assert ant.frequencies["G01"].pco_neu_m[2] == pytest.approx(0.05)
    assert tiny.receiver("UNKNOWN         NONE") is None
    assert tiny.receiver("ADVNULLANTENNA") is None
    got, notes = antennas_for(tiny, {"A": "TEST1           SCIS", "B": "NOPE", "C": ""})
    assert list(got) == ["A"] and len(notes) == 3 and "radome NONE" in notes[0]


def test_split_antenna_type():
    assert split_antenna_type("TRM41249.00     NONE") == ("TRM41249.00", "NONE")
    assert split_antenna_type("TRM41249.00     ") == ("TRM41249.00", "NONE")
    assert split_antenna_type("TRM29659.00 SCIS") == ("TRM29659.00", "SCIS")
    assert split_antenna_type("TRM29659.00", "") == ("TRM29659.00", "NONE")


def test_gzip_reads_the_same(tmp_path, tiny):
    p = tmp_path / "tiny.atx.gz"
    with gzip.open(p, "wt") as f:
        f.write("\n".join(tiny_antex()) + "\n")
    again = read_antex(p)
    assert set(again.receivers) == set(tiny.receivers)


@pytest.mark.parametrize("edit, where, message", [
    (lambda L: L.__setitem__(L.index(next(x for x in L if x.startswith("   NOAZI"))),
                             "   NOAZI    0.00   -2.00"), "NOAZI", "NOAZI has 2 values"),
    (lambda L: L.__setitem__(L.index(next(x for x in L if "NORTH / EAST / UP" in x)),
                             f"{'      1.00      x.00     50.00':<60}NORTH / EAST / UP"),
     "NORTH / EAST / UP", "not numbers"),
    (lambda L: L.remove(next(x for x in L if "END OF ANTENNA" in x)), "START OF ANTENNA", "inside the antenna"),
    (lambda L: L.remove(next(x for x in L if "START OF ANTENNA" in x)), "TYPE / SERIAL NO", "outside an antenna"),
])
def test_malformed_file_names_the_line(tmp_path, edit, where, message):
    lines = tiny_antex()
    edit(lines)
    p = tmp_path / "bad.atx"
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(AntexError, match=message) as exc:
        read_antex(p)
    text = str(exc.value)
    assert text.startswith(f"{p}:")
    ln = int(text.split(":")[1])
    assert where in lines[ln - 1] or where in "\n".join(lines[ln - 1:ln + 1])


def test_not_antex(tmp_path):
    p = tmp_path / "x.atx"
    p.write_text("hello\n")
    with pytest.raises(AntexError, match=r":1: not an ANTEX file"):
        read_antex(p)


# --- the IGS05 model of 2010 (shared data) ---------------------------------------------------------


@pytest.fixture(scope="module")
def igs05(request):
    shared = request.getfixturevalue("shared_data")
    return read_antex(shared / "antex" / "igs05.atx.gz"), shared / "antex" / "igs05.atx.gz"


def _text_block(path, antenna_type: str) -> list[str]:
    """The lines of an antenna's block in the file, straight from the text."""
    with gzip.open(path, "rt") as f:
        lines = f.read().splitlines()
    i = next(k for k, x in enumerate(lines) if x.startswith(antenna_type) and "TYPE / SERIAL NO" in x)
    j = next(k for k in range(i, len(lines)) if "END OF ANTENNA" in lines[k])
    return lines[i:j]


@pytest.mark.shared_data
@pytest.mark.parametrize("antenna_type", ["TRM41249.00     NONE", "TRM29659.00     NONE"])
def test_igs05_offsets_match_the_text(igs05, antenna_type):
    atx, path = igs05
    block = _text_block(path, antenna_type)
    ant = atx.receiver(antenna_type)
    assert not ant.radome_fallback
    for code in ("G01", "G02"):
        k = next(n for n, x in enumerate(block) if x[3:6] == code and "START OF FREQUENCY" in x)
        neu = [float(v) for v in block[k + 1][:30].split()]
        noazi = [float(v) for v in block[k + 2][8:].split()]
        f = ant.frequencies[code]
        assert f.pco_neu_m == pytest.approx(np.array(neu) * 1e-3, abs=1e-9)
        assert f.noazi_m == pytest.approx(np.array(noazi) * 1e-3, abs=1e-9)
        assert f.pcv_m.shape == (73, 19)  # DAZI 5 over 0-360, zenith 0-90 by 5
    # the values themselves, as printed in igs05.atx (mm): a check that the parsing is not only self-consistent
    expected_up = {"TRM41249.00     NONE": (55.29, 57.42), "TRM29659.00     NONE": (91.95, 120.49)}[antenna_type]
    assert ant.frequencies["G01"].pco_neu_m[2] * 1e3 == pytest.approx(expected_up[0])
    assert ant.frequencies["G02"].pco_neu_m[2] * 1e3 == pytest.approx(expected_up[1])


@pytest.mark.shared_data
def test_igs05_pcv_interpolation_between_nodes(igs05):
    atx, path = igs05
    f = atx.receiver("TRM41249.00     NONE").frequencies["G01"]
    # zenith 42.5 at azimuth 0: halfway between the azimuth-0 row's values at 40 and 45 degrees
    row0 = f.pcv_m[0]
    assert f.pcv(42.5, 0.0) == pytest.approx(0.5 * (row0[8] + row0[9]))
    assert f.pcv(40.0, 2.5) == pytest.approx(0.5 * (f.pcv_m[0, 8] + f.pcv_m[1, 8]))
    assert f.pcv(0.0, 123.0) == pytest.approx(0.0)  # the model is zero at the zenith by definition
    # a radome without its own calibration in IGS05 -> NONE's values, flagged
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fb = atx.receiver("TRM41249.00     SCIS")  # IGS05 has NONE, SCIT, TZGD
    assert fb.radome_fallback and fb.frequencies["G01"] is f
    assert len(atx.receivers) > 100 and "G05" in atx.satellites
