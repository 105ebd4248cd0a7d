"""Command line: `augnet sim ...` refuses bad input with the reason, records, and takes --nav."""

from __future__ import annotations

import csv

import pytest
from typer.testing import CliRunner

from stations.cli import sim_app

runner = CliRunner()


def test_list_names_builtins():
    res = runner.invoke(sim_app, ["list"])
    assert res.exit_code == 0
    for name in ("demo", "baseline-10km", "network-70km", "iono-storm"):
        assert name in res.output


def test_invalid_scenario_refused_with_field_value_allowed(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\nrate_hz: fast\nstations: [{id: A, lat_deg: 95, lon_deg: 0, h_m: 0}]\n")
    res = runner.invoke(sim_app, ["record", str(bad), "--out", str(tmp_path / "o")])
    assert res.exit_code == 2
    assert "stations.0.lat_deg = 95" in res.output and "less than or equal to 90" in res.output
    assert "rate_hz = 'fast'" in res.output
    assert not (tmp_path / "o").exists()
    res = runner.invoke(sim_app, ["record", "demo", "--duration", "-5", "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and "--duration" in res.output


def test_record_short(tmp_path):
    res = runner.invoke(sim_app, ["record", "baseline-10km", "--duration", "5", "--out", str(tmp_path)])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "A.obs").is_file() and (tmp_path / "B.rtcm3").is_file()
    assert "x real time" in res.output


def test_show_resolves_presets():
    res = runner.invoke(sim_app, ["show", "iono-storm"])
    assert res.exit_code == 0
    assert '"ionosphere_resolved"' in res.output and '"vtec_tecu": 60.0' in res.output


@pytest.mark.shared_data
def test_record_with_real_nav_file(shared_data, tmp_path):
    nav = shared_data / "nav" / "brdm-2023-07-11.nav"
    res = runner.invoke(sim_app, ["record", "baseline-10km", "--duration", "10", "--out", str(tmp_path),
                                  "--nav", str(nav), "--no-rtcm"])
    assert res.exit_code == 0, res.output
    rows = list(csv.DictReader(open(tmp_path / "truth.csv")))
    assert rows[0]["gpst_calendar"].startswith("2023-07-11")
    atmo = list(csv.DictReader(open(tmp_path / "atmosphere.csv")))
    sats = {r["sat"] for r in atmo}
    assert any(s.startswith("G") for s in sats) and any(s.startswith("C") for s in sats)


def test_stations_run_refuses_a_bad_caster_address():
    from stations.cli import stations_app

    res = runner.invoke(stations_app, ["run", "demo", "--caster", "localhost"])
    assert res.exit_code == 2 and "HOST:PORT" in res.output


def test_km_beyond_the_line_refused(tmp_path):
    import yaml
    from importlib import resources

    d = yaml.safe_load(resources.files("stations.scenarios").joinpath("demo.yaml").read_text())
    d["trains"][0]["start_km"] = 500.0
    d["stations"][0]["outages"] = [[30, 10]]
    p = tmp_path / "far.yaml"
    p.write_text(yaml.safe_dump(d))
    res = runner.invoke(sim_app, ["record", str(p), "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and "stations.0.outages" in res.output
    d["stations"][0]["outages"] = []
    p.write_text(yaml.safe_dump(d))
    res = runner.invoke(sim_app, ["record", str(p), "--duration", "2", "--out", str(tmp_path / "o")])
    assert res.exit_code == 2
    assert "trains.0.start_km = 500.0: beyond the end of the line (0 to 222.2" in res.output


@pytest.mark.slow
def test_stats_of_a_recorded_scenario(tmp_path):
    """`sim stats --scenario` records, then prints the station and pair tables measured on its RINEX."""
    res = runner.invoke(sim_app, ["stats", "--scenario", "baseline-10km", "--duration", "900", "--rate", "0.2",
                                  "--out", str(tmp_path / "rec")])
    assert res.exit_code == 0, res.output
    rows = [line for line in res.output.splitlines() if line.startswith("| ")]
    assert any("| A |" in r for r in rows) and any("| B |" in r for r in rows)
    pair = next(r for r in rows if "| A-B |" in r)
    assert "| 10.0 | 5 |" in pair  # 10 km, 5 s


def test_stats_refuses_nothing_to_measure():
    res = runner.invoke(sim_app, ["stats"])
    assert res.exit_code == 2 and "--scenario" in res.output
