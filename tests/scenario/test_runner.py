"""`augnet scenario run`: the whole chain on the demo line against the simulator's truth.

One shortened demo run (DEMO_S simulated seconds, written to a temporary folder with its plots) serves the
module: the report's schema and files, the PNGs, the figures the chain meets today, and the issue's
targets as a strict xfail with the figures measured on the full 600 s demo. The full run takes ~2 min on
the shared 2-core machine (`augnet scenario run demo --out DIR`); the short one ~30 s.
"""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest
from typer.testing import CliRunner

from augnet.scenario import report as R
from augnet.scenario.runner import run
from stations.scenario import ScenarioError

# 150 s: the network fixes its first baselines after ~40 s, the slower train G101 its first ambiguities ~35 s
# after the start, and both trains pass two or more virtual balises.
DEMO_S = 150
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
TRAINS = ("G101", "G303")


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    rep = run("demo", out, duration_s=DEMO_S, progress=False)
    return rep, out, json.loads((out / R.REPORT_JSON).read_text())


def test_report_json_has_every_documented_key(demo):
    rep, out, d = demo
    assert R.schema_problems(d) == []
    assert d["version"] == "augnet-scenario-report/1"
    assert d["scenario"]["name"] == "demo" and d["scenario"]["duration_s"] == DEMO_S
    assert set(d["trains"]) == set(TRAINS)
    assert len(d["baselines"]) >= 6  # six stations, each joined to its two nearest and a spanning tree
    ids = {t["id"] for t in d["targets"]}
    for tid in TRAINS:
        assert {f"{tid}.{k}" for k in ("fix_rate", "ttff", "h95", "v95", "wrong_fixes", "track_id", "balise_error",
                                       "balise_missed", "balise_false", "pl_violations")} <= ids
    assert {"network.baseline_fix", "network.wrong_fixes", "network.interpolation"} <= ids
    assert d["passed"] is all(t["pass"] is not False for t in d["targets"])
    assert d["run"]["epochs"] == DEMO_S and d["run"]["network_epochs"] >= DEMO_S - 2
    for name in d["files"]:
        assert (out / name).stat().st_size > 0, name
    rows = (out / R.EPOCHS_CSV).read_text().splitlines()
    assert len(rows) == 1 + DEMO_S * len(TRAINS)


def _png_size(path):
    data = path.read_bytes()
    assert data[:8] == PNG_SIGNATURE, path
    assert data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


def test_plots_are_png_images_with_content(demo):
    from matplotlib.image import imread

    _, out, d = demo
    for name in ("error_over_time.png", "stanford.png", "network_map.png"):
        assert name in d["files"]
        w, h = _png_size(out / name)
        assert w >= 600 and h >= 500, (name, w, h)
        img = imread(out / name)
        assert img.shape[:2] == (h, w)
        assert img[..., :3].std() > 0.05, f"{name} is blank"  # something was drawn


def test_the_chain_against_the_truth_in_the_first_150_s(demo):
    """What the chain does reach today (the issue's targets as a whole are the xfail below)."""
    rep, _, d = demo
    g101 = d["trains"]["G101"]
    for tid, f in d["trains"].items():
        assert f["session_opened_s"] == 0.0  # the first GGA (from the first SPP) opens the VRS session
        assert f["wrong_fixes"] == 0, tid
        # never a confirmed wrong track, never off the map; an unconfirmed guess 3 m off in a float epoch
        # (G303 at 27 s, HPL 17 m spans both tracks) is counted by the target, in the xfail below
        tr = f["track_id"]
        assert tr["confirmed_wrong"] == 0 and tr["off_map"] == 0, (tid, tr)
        assert tr["wrong"] <= 0.02 * tr["epochs_with_position"], (tid, tr)
        assert f["track_id"]["epochs_with_position"] == DEMO_S
        assert f["virtual_balises"]["false"] == 0
        assert f["virtual_balises"]["captured"] >= 1  # G101 at km 86 (135 s), G303 at 156 and 151
        assert f["virtual_balises"]["capture_error_m"]["max"] <= R.TARGET_BALISE_ERROR_M
        age = f["correction_age_s"]
        assert age["p50"] == 1.0 and age["over_limit"] == 0  # low-latency rover: the previous epoch's VRS
        assert f["vrs_moves"] >= DEMO_S // 10 - 3  # the session follows the GGA at most every 10 s
    for tid, f in d["trains"].items():
        pl = f["protection_level"]
        assert pl["h_error_over_hpl"] + pl["v_error_over_vpl"] == 0, (tid, pl)
    # G101 (160 km/h, 10-20 km from STA2) fixes within seconds of usable corrections and holds the fix while
    # its VRS moves with it every 10 s (the same base at a new point: ambiguities kept) and while a late VRS
    # epoch makes it reuse the previous one (correction age 2 s)
    assert g101["ttff_s"] is not None and g101["ttff_s"] <= 30.0
    assert g101["fix_rate_after_first_fix"] >= R.TARGET_FIX_RATE
    assert g101["correction_age_s"]["max"] >= 2.0
    assert g101["horizontal_error_m"]["p95"] <= R.TARGET_H95_M
    assert g101["vertical_error_m"]["p95"] <= R.TARGET_V95_M
    assert g101["virtual_balises"]["capture_error_m"]["max"] <= R.TARGET_BALISE_ERROR_M
    assert d["network"]["wrong_fixes"] == 0 and d["network"]["checked"] > 5000
    assert d["interpolation"]["dd_iono_error_m"]["n"] > 1000


@pytest.mark.xfail(strict=True, raises=AssertionError, reason=(
    "issue 8's targets not all met. Full 600 s demo, measured 2026-11-22 at 2ff8564 (centre learning the day's "
    "ionosphere level; onboard counting validated partial fixes towards confirmation): 20 of 23 targets pass - "
    "no wrong fix (trains or network), no epoch beyond its protection level, fixed after the first fix 99.62 / "
    "99.64 %, H95 1.0-1.1 / V95 2.0-2.9 cm, time to (re-)fix G101 7.5 s, right track in every epoch, network "
    "baselines fix in a median 48 s. Not met: G303 time to (re-)fix 17.5 s (its first fix at 33 s: the VRS "
    "carries 8 usable satellites until 50 s and the complete fix's position sigma stays just over the 3 cm "
    "gate); interpolated DD ionosphere 1.012 cm RMS (goal 1 cm); G101's km 81 balise passed before its first "
    "confirmed position (counted missed)."))
def test_must_show_the_demo_meets_the_targets(demo):
    rep, _, d = demo
    failed = [(t["id"], t["measured"], t["target"]) for t in d["targets"] if t["pass"] is False]
    assert failed == []


def test_unknown_scenario_is_refused_naming_it(tmp_path):
    with pytest.raises(ScenarioError, match="no-such-line"):
        run("no-such-line", tmp_path, progress=False)
    with pytest.raises(ScenarioError, match="duration"):
        run("demo", tmp_path, duration_s=-5, progress=False)
    assert not (tmp_path / R.REPORT_JSON).exists()


def test_cli_refuses_an_unknown_scenario_and_runs_a_short_one(tmp_path):
    from augnet.cli import _mount, app

    _mount()
    runner = CliRunner()
    bad = runner.invoke(app, ["scenario", "run", "no-such-line", "--out", str(tmp_path / "x")])
    assert bad.exit_code == 2 and "no-such-line" in bad.output
    good = runner.invoke(app, ["scenario", "run", "baseline-10km", "--out", str(tmp_path / "b"), "--duration", "15",
                               "--no-plots", "--quiet"])
    assert good.exit_code == 0, good.output
    d = json.loads((tmp_path / "b" / R.REPORT_JSON).read_text())
    assert R.schema_problems(d) == [] and d["trains"] == {} and d["run"]["epochs"] == 15
    assert "network.wrong_fixes" in good.output  # the targets table
    strict = runner.invoke(app, ["scenario", "run", "baseline-10km", "--out", str(tmp_path / "s"), "--duration", "2",
                                 "--no-plots", "--quiet", "--strict"])
    # two epochs: no baseline can be fixed yet (a fix needs confirming epochs), so the network targets cannot
    # pass; --strict says so
    assert strict.exit_code == 1, strict.output


def test_schema_problems_name_what_is_wrong(demo):
    _, _, d = demo
    broken = json.loads(json.dumps(d))
    del broken["trains"]["G101"]["wrong_fixes"]
    broken["targets"][0]["pass"] = "yes"
    broken["version"] = "augnet-scenario-report/0"
    problems = R.schema_problems(broken)
    assert "trains.G101: missing 'wrong_fixes'" in problems
    assert "targets[0].pass must be true, false or null" in problems
    assert any("version" in p for p in problems)
    del broken["interpolation"]
    assert R.schema_problems(broken) == ["missing key 'interpolation'"]
