"""RINEX 3 navigation: the real multi-GNSS files read, and write -> read is exact."""

from __future__ import annotations

import gzip
import math

import pytest

from augnet.gnss.ephemeris import Ephemeris, NavigationData
from augnet.gnss.rinex.nav import NavHeader, read_nav, write_nav

NAV_FILES = [
    ("nav/brdm-2023-07-11.nav", 3.02),
    ("rinex/static-1m-2024/base.nav", 3.04),
    ("rinex/rtk-base-rover-yokohama-2021/nav-SEPT2650.21P", 3.04),
]


def _count_records(path, letters):
    return sum(1 for line in path.read_text().splitlines() if line[:1] in letters and line[1:3].strip().isdigit())


@pytest.mark.parametrize("name,version", NAV_FILES)
def test_real_nav_files_read_and_round_trip(shared_data, tmp_path, name, version):
    path = shared_data / name
    nav = read_nav(path)
    assert nav.header.version == version
    # Every GPS/Galileo/BDS/QZSS record kept, every GLONASS/SBAS one counted as skipped.
    assert len(nav.ephemerides) == _count_records(path, "GECJ")
    assert sum(nav.skipped.values()) == _count_records(path, "RSI")
    out = tmp_path / "rt.nav"
    write_nav(out, nav.ephemerides, nav.header)
    again = read_nav(out)
    assert again.ephemerides == nav.ephemerides  # every parameter identical
    assert again.header.leap_seconds == nav.header.leap_seconds
    kept = [(c, lab) for c, lab in nav.header.extra if lab in ("IONOSPHERIC CORR", "TIME SYSTEM CORR")]
    assert [(c.rstrip(), lab) for c, lab in again.header.extra if lab in ("IONOSPHERIC CORR", "TIME SYSTEM CORR")] == [
        (c.rstrip(), lab) for c, lab in kept
    ]


def test_brdm_2023_field_mapping(shared_data):
    """Spot values from the file text, per system (units: radians, seconds, metres)."""
    nav = read_nav(shared_data / "nav" / "brdm-2023-07-11.nav")
    assert nav.header.leap_seconds == 18
    assert nav.skipped == {"R": 449}
    g01 = next(e for e in nav.ephemerides if e.sat == "G01")
    assert (g01.week, g01.toe, g01.toc, g01.iode, g01.iodc) == (2270, 172800.0, 172800.0, 84, 84)
    assert g01.af0 == 0.17365859821e-3 and g01.tgd == 0.46566128731e-8 and g01.health == 60
    assert g01.sqrt_a == 0.51536449070e4 and g01.fit_interval_h == 4.0 and g01.transmission_time == 172776.0
    e18 = next(e for e in nav.ephemerides if e.sat == "E18")
    # Galileo: RINEX week 2270 (GPS-aligned) is GST week 1246; toc 2023-07-10 23:40 = sow 171600.
    assert (e18.week, e18.toe, e18.toc, e18.data_sources) == (1246, 171600.0, 171600.0, 513)
    assert e18.bgd_e5a_e1 == -0.16298145056e-8 and e18.bgd_e5b_e1 == -0.20954757929e-8
    assert e18.toe_gpst == e18.toc_gpst
    c = next(e for e in nav.ephemerides if e.system == "C")
    # BDS: week and toc in BDT; the toc calendar epoch is BDT too, so toe_gpst = toc_gpst when equal.
    assert c.week == 914 and c.toc == c.toe and c.toe_gpst == c.toc_gpst
    assert c.tgd1 != 0.0 and c.iodc >= 0


def test_synthetic_round_trip_all_systems_and_gzip(tmp_path):
    base = dict(
        week=2300, toe=7200.0, toc=7200.0, af0=-1.234567890123e-4, af1=2.5e-12, af2=0.0, iode=17,
        crs=-12.5, delta_n=4.1e-9, m0=1.1, cuc=-1.5e-6, e=0.0123, cus=7.5e-6, sqrt_a=5153.7, cic=1e-8,
        omega0=-2.1, cis=-2e-8, i0=0.96, crc=250.0, omega=0.7, omega_dot=-8e-9, idot=1e-10, accuracy_m=2.0,
        transmission_time=3600.0,
    )
    ephs = [
        Ephemeris(system="G", prn=7, tgd=-1.1e-8, iodc=273, codes_on_l2=1, fit_interval_h=4.0, **base),
        Ephemeris(system="E", prn=11, bgd_e5a_e1=1.2e-9, bgd_e5b_e1=1.4e-9, data_sources=517, **base),
        Ephemeris(system="C", prn=59, tgd1=-5e-9, tgd2=3e-9, iodc=1, **base),
        Ephemeris(system="J", prn=2, tgd=2e-9, iodc=900, **base),
        # toc in the previous week from toe (week roll-over between toc and toe)
        Ephemeris(system="G", prn=8, **{**base, "toe": 0.0, "toc": 604784.0}),
    ]
    for name in ("syn.nav", "syn.nav.gz"):
        out = tmp_path / name
        write_nav(out, ephs, NavHeader(leap_seconds=18, comments=["written by augnet tests"]))
        back = read_nav(out).ephemerides
        assert len(back) == len(ephs)
        for a, b in zip(ephs, back):
            for f in a.__dataclass_fields__:
                va, vb = getattr(a, f), getattr(b, f)
                if isinstance(va, float):
                    assert math.isclose(va, vb, rel_tol=1e-12, abs_tol=1e-30), (a.sat, f, va, vb)
                else:
                    assert va == vb, (a.sat, f)
    assert back[4].toc_gpst == back[4].toe_gpst - 16.0
    # The file works as input to orbit computation (a BDS GEO id among them).
    nav = NavigationData(back)
    assert nav.table.is_geo.tolist() == [False, False, True, False, False]


def test_rinex2_gps_nav_gzip(shared_data):
    path = shared_data / "rinex" / "nl-network-2021" / "cbw10010.21n.gz"
    nav = read_nav(path)
    assert nav.header.version == 2.11 and nav.header.system == "G"
    lines = gzip.decompress(path.read_bytes()).decode().splitlines()
    body = lines[next(i for i, line in enumerate(lines) if "END OF HEADER" in line) + 1 :]
    assert len(nav) == len(body) // 8
    first = nav.ephemerides[0]
    # " 1 21  1  1  2  0  0.0 7.874774746600D-04-5.911715561520D-12 0.000000000000D+00"
    assert (first.sat, first.week, first.toe, first.toc) == ("G01", 2138, 439200.0, 439200.0)
    assert first.af0 == 7.874774746600e-04 and first.tgd == 5.122274160390e-09 and first.iodc == 52
    # A record timed in the previous year (2020-12-31 23:59:44) lands in the same GPS week.
    g07 = next(e for e in nav if e.sat == "G07")
    assert g07.toc == 431984.0 and g07.toe == 431984.0


def test_week_comes_from_the_toc_epoch_not_the_week_field(tmp_path):
    """Some writers put the GST week (not the GPS-aligned one) in Galileo records, old GPS files a
    10-bit week: the toc calendar epoch fixes the week either way."""
    e = Ephemeris(system="E", prn=5, week=1246, toe=172800.0, toc=172800.0, af0=1e-4, af1=0.0, af2=0.0,
                  iode=30, crs=1.0, delta_n=3e-9, m0=0.1, cuc=1e-6, e=1e-4, cus=1e-6, sqrt_a=5440.6,
                  cic=1e-8, omega0=1.0, cis=1e-8, i0=0.97, crc=100.0, omega=0.5, omega_dot=-5e-9,
                  idot=1e-10, data_sources=517)
    g = e.replace(system="G", week=2270, data_sources=0)
    write_nav(tmp_path / "a.nav", [e, g])
    lines = (tmp_path / "a.nav").read_text().splitlines()
    hits = [k for k, line in enumerate(lines) if "2.270000000000E+03" in line]
    assert len(hits) == 2  # orbit line 5 of each record
    lines[hits[0]] = lines[hits[0]].replace("2.270000000000E+03", "1.246000000000E+03")  # GST week
    lines[hits[1]] = lines[hits[1]].replace("2.270000000000E+03", "2.220000000000E+02")  # 2270 mod 1024
    (tmp_path / "b.nav").write_text("\n".join(lines) + "\n")
    assert read_nav(tmp_path / "b.nav").ephemerides == [e, g]
