"""`augnet rtk` refuses unusable inputs with exit status 2 and a message; coordinate parsing."""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

from augnet.gnss.geometry import ecef_to_geodetic
from augnet.onboard.inputs import InputError, klobuchar_from_header, parse_position


def _cli(args):
    from augnet.cli import _mount, app

    _mount()
    return CliRunner().invoke(app, ["rtk", *args])


def test_parse_position_accepts_ecef_and_geodetic():
    p = parse_position("-3817680.9841,3562840.0688,3650158.4543")
    assert p == pytest.approx([-3817680.9841, 3562840.0688, 3650158.4543])
    q = parse_position("35.134707705, 136.977577939, 104.853")
    llh = ecef_to_geodetic(q)
    assert np.degrees(llh[:2]) == pytest.approx([35.134707705, 136.977577939], abs=1e-9)
    assert llh[2] == pytest.approx(104.853, abs=1e-4)


@pytest.mark.parametrize("text", ["", "1,2", "a,b,c", "95,10,0", "1e6,1e6,1e6", "nan,0,0"])
def test_parse_position_refuses_nonsense(text):
    with pytest.raises(InputError):
        parse_position(text)


def test_klobuchar_coefficients_from_a_rinex3_header():
    extra = [("GPSA   1.8626E-08  2.2352E-08 -1.1921E-07 -5.9605E-08       ", "IONOSPHERIC CORR"),
             ("GPSB   1.2902E+05  1.6384E+05 -1.9661E+05 -2.6214E+05       ", "IONOSPHERIC CORR"),
             ("GAL    1.6175E+02  6.6016E-01  1.9379E-02  0.0000E+00       ", "IONOSPHERIC CORR")]
    a, b = klobuchar_from_header(extra)
    assert a == pytest.approx((1.8626e-8, 2.2352e-8, -1.1921e-7, -5.9605e-8))
    assert b == pytest.approx((1.2902e5, 1.6384e5, -1.9661e5, -2.6214e5))


def test_missing_files_exit_2_with_a_message(tmp_path):
    r = _cli(["--rover", str(tmp_path / "nope.obs"), "--base", str(tmp_path / "b.obs"),
              "--nav", str(tmp_path / "n.nav"), "--out", str(tmp_path / "o.csv")])
    assert r.exit_code == 2
    assert "cannot read" in r.output


def test_corrupt_observation_file_exit_2(tmp_path, shared_data):
    bad = tmp_path / "bad.obs"
    bad.write_text("this is not RINEX\n" * 5)
    nav = shared_data / "rinex/static-1m-2024/base.nav"
    r = _cli(["--rover", str(bad), "--base", str(bad), "--nav", str(nav), "--base-pos", "35,136,100",
              "--out", str(tmp_path / "o.csv")])
    assert r.exit_code == 2
    assert "cannot read observations" in r.output


@pytest.mark.parametrize("assignment, named", [("no_such=1", "no_such"), ("ionosphere=sometimes", "ionosphere"),
                                               ("ratio_threshold=high", "ratio_threshold"), ("ratio_threshold", "NAME=VALUE")])
def test_a_bad_setting_exits_2_naming_it(tmp_path, assignment, named):
    r = _cli(["--rover", str(tmp_path / "r.obs"), "--base", str(tmp_path / "b.obs"), "--nav", str(tmp_path / "n.nav"),
              "--out", str(tmp_path / "o.csv"), "--opt", "min_fix_ambiguities=5", "--opt", assignment])
    assert r.exit_code == 2
    assert named in r.output
