"""A short fault-injection campaign end to end: the report's structure, and injected faults detected.

One pair on the iono-storm line (L2: 3 stations, one 250 km/h train, quiet ionosphere, 300 s warm-up of the
network, 60 s of train) with a 30 % odometer slide on wet rail and then a 1 ns/s satellite clock ramp; the
same pair again with the fusion's residual check disabled: the slide's alarm must then be missing, which the
detection assertion catches (the test can fail). Two simulations, ~1 min CPU on a quiet machine.
"""

from __future__ import annotations

import json

import pytest

from augnet.onboard.along_track_fusion import METHODS
from augnet.scenario.campaign import (CAMPAIGN_JSON, CAMPAIGN_MD, CROSS_TRACK, FUSED_METHODS, STANFORD_PNG, Campaign,
                                      expand, run_campaign, run_pair)
from tests.conftest import LONG_RUN_TIMEOUT_S

pytestmark = [pytest.mark.slow, pytest.mark.timeout(LONG_RUN_TIMEOUT_S)]

SLIDE_AT_S, SLIDE_UNTIL_S = 45.0, 48.0
TRAIN = {"id": "D7", "track": 1, "start_km": 10.0, "start_speed_kmh": 250, "speed_kmh": 250}


def short_campaign() -> Campaign:
    return Campaign.model_validate({"name": "short", "warm_up_s": 300, "duration_s": 60, "cases": [
        {"id": "slide-ramp", "scenario": "iono-storm", "seeds": [1], "set": {
            "rail": "wet", "errors": {"ionosphere": {"level": "quiet"}}, "trains": [TRAIN],
            "faults": [{"kind": "odometer_slide", "train": "D7", "at_s": SLIDE_AT_S, "until_s": SLIDE_UNTIL_S,
                        "slide_fraction": 0.3},
                       {"kind": "satellite_clock_ramp", "satellite": "auto", "at_s": 52.0, "until_s": 58.0,
                        "ramp_ns_per_s": 1.0}]}}]})


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    out = tmp_path_factory.mktemp("campaign")
    doc = run_campaign(short_campaign(), out)
    return out, doc


def test_report_structure(campaign):
    out, doc = campaign
    assert json.loads((out / CAMPAIGN_JSON).read_text()) == doc
    md = (out / CAMPAIGN_MD).read_text()
    for m in (*METHODS, CROSS_TRACK):
        assert (out / STANFORD_PNG.format(method=m)).stat().st_size > 1000
        assert f"| {m} |" in md
        f = doc["summary"]["methods"][m]
        assert f["epochs"] == 60 and 0 <= f["available"] <= 60  # every epoch of the pair
        assert set(f["fault_outcomes"]) == {"alarm", "missed", "protected", "unavailable"}
        assert sum(f["stanford"].values()) <= 60
    assert {c["id"] for c in doc["summary"]["checks"]} >= {"hmi_fused_along", "hmi_cross", "availability_wm",
                                                          "tta_train_max_s", "tta_rbc_max_s"}
    assert [p["pair"] for p in doc["pairs"]] == ["slide-ramp/s1"]
    assert doc["summary"]["fault_kinds"] == ["odometer_slide", "satellite_clock_ramp"]


def slide_outcomes(faults):
    (slide,) = [f for f in faults if f["kind"] == "odometer_slide"]
    return slide["methods"]


def test_slide_alarmed_within_a_second_and_no_hmi(campaign):
    _, doc = campaign
    pair = doc["pairs"][0]
    wm = pair["figures"]["D7"]["weighted_median"]
    out = slide_outcomes(pair["faults"])
    for m in FUSED_METHODS:
        assert out[m]["outcome"] == "alarm", (m, out[m])  # the train had a position to withdraw
        assert out[m]["tta_train_s"] <= 1.0 and out[m]["tta_rbc_s"] <= 2.0, out[m]
        assert out[m]["tta_rbc_s"] > out[m]["tta_train_s"]
    assert wm["hmi"] == 0
    assert out["gnss_raim"]["outcome"] == "protected", out["gnss_raim"]  # GNSS alone reads no odometer


def test_slide_with_the_residual_check_disabled_goes_unalarmed():
    cp = short_campaign()
    (pair,) = expand(cp)
    res = run_pair(pair, cp.warm_up_s, fusion={"residual_gate_sigma": 1e9})
    out = slide_outcomes(res.faults)
    assert all(out[m]["outcome"] in ("missed", "protected") for m in FUSED_METHODS), out
    assert any(out[m]["tta_train_s"] is None for m in FUSED_METHODS)
