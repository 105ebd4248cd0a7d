"""`augnet scenario run`: the whole chain on the demo line against the simulator's truth.

One full demo run (the 600 s scenario after the stations' and the centre's 300 s warm-up, written to a
temporary folder with its plots; ~1 min on the shared 2-core machine, as `augnet scenario run demo --out DIR`)
serves the module: the report's schema and files, the PNGs, the figures the chain meets, and the issue's
targets. A few short runs show what the warm-up changes: trains switched on into a running centre against
trains started with a cold one.
"""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest
from typer.testing import CliRunner

from augnet.scenario import report as R
from augnet.scenario.runner import DEFAULT_WARM_UP_S, run, simulate
from stations.scenario import ScenarioError
from tests.conftest import LONG_RUN_TIMEOUT_S

pytestmark = [pytest.mark.slow, pytest.mark.timeout(LONG_RUN_TIMEOUT_S)]

DEMO_S = 600  # the demo scenario's own duration
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
TRAINS = ("G101", "G303")


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    rep = run("demo", out, progress=False)
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
    run_ = d["run"]
    assert run_["epochs"] == DEMO_S and run_["warm_up_s"] == DEFAULT_WARM_UP_S == 300.0
    assert run_["centre_start_s"] == -300.0 and run_["world_epochs"] == DEMO_S + 300
    assert run_["network_epochs"] >= DEMO_S + 300 - 2
    assert {"warm_up", "baseline_first_fix", "ttff"} <= set(d["definitions"])
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
    along = [f"stanford_along_{m}.png" for m in ("gnss_raim", "median", "weighted_median", "residual_weighted_median")]
    for name in ("error_over_time.png", "stanford.png", "network_map.png", *along):
        assert name in d["files"]
        w, h = _png_size(out / name)
        assert w >= 600 and h >= 500, (name, w, h)
        img = imread(out / name)
        assert img.shape[:2] == (h, w)
        assert img[..., :3].std() > 0.05, f"{name} is blank"  # something was drawn


def test_the_chain_against_the_truth_on_the_demo(demo):
    """What the chain reaches on the demo, target by target beside the issue's own (the xfail below)."""
    rep, _, d = demo
    for tid, f in d["trains"].items():
        assert f["session_opened_s"] == 0.0  # the first GGA (from the first SPP) opens the VRS session
        # a running centre: the first VRS epoch carries enough corrected satellites (~1 s link), the fix follows
        assert f["corrections_usable_s"] <= 3.0, tid
        assert f["acquisitions"][0]["time_s"] <= R.TARGET_TTFF_S, tid
        assert f["acquisition_time_median_s"] <= R.TARGET_TTFF_S, tid
        assert f["wrong_fixes"] == 0, tid
        assert f["fix_rate_after_first_fix"] >= R.TARGET_FIX_RATE, tid
        assert f["horizontal_error_m"]["p95"] <= R.TARGET_H95_M and f["vertical_error_m"]["p95"] <= R.TARGET_V95_M
        # the right track in every epoch with a position, never off the map; none in the tunnel
        tr = f["track_id"]
        assert tr["wrong"] == 0 and tr["off_map"] == 0 and tr["confirmed_wrong"] == 0, (tid, tr)
        assert tr["epochs_with_position"] == f["epochs"] - f["epochs_without_sky"], tid
        vb = f["virtual_balises"]
        assert vb["false"] == 0 and vb["missed_with_gnss"] == 0, (tid, vb["missed_ids"])
        assert vb["captured"] >= 5  # G101 from km 81 (22.5 s) on, G303 from km 156 (50 s) on
        assert vb["capture_error_m"]["max"] <= R.TARGET_BALISE_ERROR_M
        pl = f["protection_level"]
        assert pl["h_error_over_hpl"] + pl["v_error_over_vpl"] == 0, (tid, pl)
        age = f["correction_age_s"]
        assert age["p50"] == 1.0 and age["over_limit"] == 0  # low-latency rover: the previous epoch's VRS
        assert f["vrs_moves"] >= tr["epochs_with_position"] // 10 - 5  # the session follows the GGA every 10 s
    # G101 holds its fix while a late VRS epoch makes it reuse the previous one (correction age 2 s), and
    # passes its km 81 balise 22.5 s after switching on, with its fix
    g101 = d["trains"]["G101"]
    assert g101["correction_age_s"]["max"] >= 2.0
    assert "VB-L1-1-081.000" in [e["id"] for e in g101["virtual_balises"]["events"]]
    assert g101["virtual_balises"]["missed_ids"] == g101["virtual_balises"]["outage_ids"] == ["VB-L1-1-101.000"]
    # the centre's figures run from its own cold start, 300 s before the trains
    assert d["network"]["wrong_fixes"] == 0 and d["network"]["checked"] > 50000
    for name, b in d["baselines"].items():
        assert b["first_fix_s"] is not None and 0.0 < b["first_fix_s"] <= DEMO_S + 300.0, name
    assert d["interpolation"]["dd_iono_error_m"]["n"] > 10000


def test_must_show_the_demo_meets_the_targets(demo):
    """Issue 8's targets, all 23. Measured 2026-11-22 (full 600 s demo after the 300 s warm-up): no wrong fix
    (trains and network), no epoch beyond its protection level, right track in every epoch, fixed after the first
    fix 99.63 / 99.66 %, H95 0.9 / V95 1.9-2.6 cm, time to (re-)fix G101 3.5 s, G303 4.5 s, every balise passed
    with GNSS captured within 9 mm, network arcs fix in a median 29 s from the centre's cold start; interpolated
    DD ionosphere 0.35 cm RMS (goal 1 cm; 1.03 cm while each point's corrections came from its four nearest
    stations, see augnet.centre.vrs.SUBNET_STATIONS)."""
    rep, _, d = demo
    failed = [(t["id"], t["measured"], t["target"]) for t in d["targets"] if t["pass"] is False]
    assert failed == []


def test_trains_switched_on_into_a_running_centre_against_a_cold_one():
    """The warm-up is what the trains' first figures measure: 25 s of the demo after a 60 s warm-up, and with
    the centre started cold together with the trains (--warm-up 0). Cold, the network fixes nothing before it
    has measured the ionosphere's rate and the VRS carries too few corrected satellites for 11-17 s or more;
    warm, the trains' first VRS epoch (2 s) is usable and they fix within seconds. The baselines' first fix is counted
    from the centre's start."""
    warm = R.build(simulate("demo", duration_s=25, warm_up_s=60))
    cold = R.build(simulate("demo", duration_s=25, warm_up_s=0))
    assert warm.run["warm_up_s"] == 60.0 and warm.run["centre_start_s"] == -60.0 and warm.run["epochs"] == 25
    assert cold.run["warm_up_s"] == 0.0 and cold.run["world_epochs"] == cold.run["network_epochs"] == 25
    for tid in TRAINS:
        w, c = warm.trains[tid], cold.trains[tid]
        assert w["epochs"] == c["epochs"] == 25
        assert w["corrections_usable_s"] == 2.0 and w["first_fix_s"] is not None and w["first_fix_s"] <= 15.0, tid
        assert c["corrections_usable_s"] is None or c["corrections_usable_s"] >= 10.0, tid
        assert c["first_fix_s"] is None or c["first_fix_s"] > w["first_fix_s"], tid
    # cold, no baseline commits a fix before the ionosphere's rate is measured (~11 s after the centre starts)
    assert all(b["first_fix_s"] is None or b["first_fix_s"] >= 10.0 for b in cold.baselines.values())
    fixed = [b["first_fix_s"] for b in warm.baselines.values() if b["first_fix_s"] is not None]
    assert fixed and all(0.0 < x <= 85.0 for x in fixed)  # since the centre's start, 60 s before the trains


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
    assert d["run"]["warm_up_s"] == 0.0  # no train: the run is the centre's own cold start
    warm = runner.invoke(app, ["scenario", "run", "baseline-10km", "--out", str(tmp_path / "w"), "--duration", "5",
                               "--warm-up", "10", "--no-plots", "--quiet"])
    assert warm.exit_code == 0, warm.output
    d = json.loads((tmp_path / "w" / R.REPORT_JSON).read_text())
    assert d["run"]["warm_up_s"] == 10.0 and d["run"]["world_epochs"] == 15 and d["run"]["epochs"] == 5
    assert "warm-up" in warm.output
    bad_warm = runner.invoke(app, ["scenario", "run", "demo", "--out", str(tmp_path / "x"), "--warm-up", "-3"])
    assert bad_warm.exit_code == 2 and "warm-up" in bad_warm.output
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
