"""Scenario files: built-ins load, invalid files are refused naming field, value and what is allowed."""

from __future__ import annotations

import pytest
import yaml

from stations.scenario import (BUILTIN_SCENARIOS, ScenarioError, load_scenario, parse_scenario,
                               resolve_ionosphere, resolved_dict)


@pytest.mark.parametrize("name", BUILTIN_SCENARIOS)
def test_builtins_load(name):
    sc = load_scenario(name)
    assert sc.name == name
    assert sc.n_epochs > 0
    assert resolved_dict(sc)["errors"]["ionosphere_resolved"]["vtec_tecu"] >= 0


def test_demo_matches_the_brief():
    sc = load_scenario("demo")
    on_line = [s for s in sc.stations if s.km is not None]
    off_line = [s for s in sc.stations if s.km is None]
    assert len(on_line) == 4 and len(off_line) == 2
    kms = sorted(s.km for s in on_line)
    assert all(60 <= b - a <= 80 for a, b in zip(kms, kms[1:]))
    assert sorted(t.speed_kmh for t in sc.trains) == [160, 300]
    tunnels = [b for b in sc.line.blockages if b.kind == "tunnel"]
    assert len(tunnels) == 1 and tunnels[0].end_km - tunnels[0].start_km == pytest.approx(2.0)


def test_network_has_a_check_receiver():
    sc = load_scenario("network-70km")
    assert any(s.id.startswith("check") for s in sc.stations)


def _demo_dict():
    from importlib import resources
    return yaml.safe_load(resources.files("stations.scenarios").joinpath("demo.yaml").read_text())


def test_bad_enum_names_field_value_and_allowed(tmp_path):
    d = _demo_dict()
    d["errors"]["ionosphere"]["level"] = "stormy"
    p = tmp_path / "bad.yaml"
    p.write_text(yaml.safe_dump(d))
    with pytest.raises(ScenarioError) as exc:
        load_scenario(p)
    msg = str(exc.value)
    assert "bad.yaml" in msg
    assert "errors.ionosphere.level" in msg
    assert "'stormy'" in msg
    for allowed in ("'off'", "'quiet'", "'active'", "'storm'"):
        assert allowed in msg


def test_bad_number_and_unknown_field_and_signal():
    d = _demo_dict()
    d["trains"][0]["speed_kmh"] = 900
    d["stations"][0]["mast_heigth"] = 3
    d["signals"]["G"] = ["1C", "9Z"]
    with pytest.raises(ScenarioError) as exc:
        parse_scenario(d, "x.yaml")
    msg = str(exc.value)
    assert "trains.0.speed_kmh = 900" in msg and "less than or equal to 400" in msg
    assert "stations.0.mast_heigth" in msg and "unknown field" in msg
    assert "'9Z'" in msg


def test_inconsistent_references_are_refused():
    d = _demo_dict()
    d["faults"] = [{"kind": "station_outage", "at_s": 10, "station": "NOPE"}]
    with pytest.raises(ScenarioError, match="NOPE"):
        parse_scenario(d)
    d = _demo_dict()
    d["line"]["blockages"][0]["end_km"] = 99.0
    with pytest.raises(ScenarioError, match=r"line.blockages.0.*end_km"):
        parse_scenario(d)
    d = _demo_dict()
    d["stations"][1]["id"] = d["stations"][0]["id"]
    with pytest.raises(ScenarioError, match="unique"):
        parse_scenario(d)


def test_receiver_events_by_receiver():
    """errors.by_receiver (decision 0273): a class entry, then a named receiver's entry over it; a rate left out
    keeps errors' own; an unknown receiver or one named twice is refused."""
    from stations.scenario import receiver_events

    d = _demo_dict()
    d["errors"].update(phase_resets_per_hour=0.3, unflagged_slips_per_hour=0.2, data_gaps_per_hour=0.3)
    d["errors"]["by_receiver"] = [{"receivers": ["trains"], "announced": True, "data_gaps_per_hour": 1.0},
                                  {"receivers": ["G303"], "unflagged_slips_per_hour": 0.0}]
    sc = parse_scenario(d)
    ev = dict(zip(["STA1", "G101", "G303"], receiver_events(sc.errors, [("STA1", "station"), ("G101", "train"),
                                                                         ("G303", "train")])))
    assert (ev["STA1"].announced, ev["STA1"].data_gaps_per_hour, ev["STA1"].unflagged_slips_per_hour) == (False, 0.3, 0.2)
    assert (ev["G101"].announced, ev["G101"].data_gaps_per_hour, ev["G101"].phase_resets_per_hour) == (True, 1.0, 0.3)
    assert (ev["G303"].announced, ev["G303"].unflagged_slips_per_hour, ev["G303"].data_gaps_per_hour) == (True, 0.0, 1.0)
    assert resolved_dict(sc)["errors"]["by_receiver"][0]["receivers"] == ["trains"]
    d["errors"]["by_receiver"] = [{"receivers": ["G999"], "announced": True}]
    with pytest.raises(ScenarioError, match="G999"):
        parse_scenario(d)
    d["errors"]["by_receiver"] = [{"receivers": ["G101"]}, {"receivers": ["G101", "STA1"]}]
    with pytest.raises(ScenarioError, match="more than one entry"):
        parse_scenario(d)
    d["errors"]["by_receiver"] = [{"receivers": ["trains"], "announced": "sometimes"}]
    with pytest.raises(ScenarioError, match=r"errors.by_receiver.0.announced"):
        parse_scenario(d)


def test_missing_file_and_bad_yaml(tmp_path):
    with pytest.raises(ScenarioError, match="no such file"):
        load_scenario(tmp_path / "none.yaml")
    p = tmp_path / "broken.yaml"
    p.write_text("name: [unclosed\n")
    with pytest.raises(ScenarioError, match="not valid YAML"):
        load_scenario(p)


def test_ionosphere_explicit_numbers_override_preset():
    d = _demo_dict()
    d["errors"]["ionosphere"] = {"level": "storm", "vtec_tecu": 80.0}
    sc = parse_scenario(d)
    r = resolve_ionosphere(sc.errors.ionosphere)
    assert r["vtec_tecu"] == 80.0
    assert r["gradient_tecu_per_1000km"] > resolve_ionosphere(
        parse_scenario(_demo_dict()).errors.ionosphere)["gradient_tecu_per_1000km"]


def test_readme_example_is_valid():
    from pathlib import Path

    text = (Path(__file__).resolve().parents[2] / "stations" / "README.md").read_text()
    block = text.split("```yaml\n", 1)[1].split("```", 1)[0]
    sc = parse_scenario(yaml.safe_load(block), "README.md")
    assert sc.trains[0].speed_profile[0].speed_kmh == 120
    assert sc.faults[0].satellite == "G05"
    from stations.world import World
    w = World(sc.model_copy(update=dict(duration_s=3.0)))
    blk = w.run()[0]
    assert blk.observed.any()


def test_builtin_geometry():
    import numpy as np

    from stations.world import World

    def dist(w, a, b):
        ids = w.receiver_ids
        return np.linalg.norm(w.receivers[ids.index(a)].ecef[0] - w.receivers[ids.index(b)].ecef[0]) / 1e3

    w = World(load_scenario("network-70km").model_copy(update=dict(duration_s=1.0)))
    for st in ("NORTH", "EAST", "SOUTH", "WEST"):
        assert 34.0 < dist(w, "check1", st) < 36.0
    assert 69.0 < dist(w, "NORTH", "SOUTH") < 71.0 and 69.0 < dist(w, "EAST", "WEST") < 71.0
    w = World(load_scenario("demo").model_copy(update=dict(duration_s=1.0)))
    on_line = ["STA1", "STA2", "STA3", "STA4"]
    gaps = [dist(w, a, b) for a, b in zip(on_line, on_line[1:])]
    assert all(60.0 < g < 75.0 for g in gaps)
    # off-line stations are well off the line (2-D geometry for the interpolation)
    tl = w.track
    from augnet.gnss.geometry import ecef_to_geodetic
    for sid in ("OFF1", "OFF2"):
        llh = ecef_to_geodetic(w.receivers[w.receiver_ids.index(sid)].ecef[0])
        enu = np.array([[*tl.geodetic_to_plane(np.degrees(llh[0]), np.degrees(llh[1])), llh[2]]])
        _, _, d = tl.nearest_track(enu)
        assert d[0] > 15e3
