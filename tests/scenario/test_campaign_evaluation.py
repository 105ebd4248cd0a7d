"""The campaign's evaluation on hand-made series: every outcome a fault can have is told apart."""

import numpy as np
import pytest

from augnet.scenario.campaign import (expand, fault_outcome, load_campaign, method_figures, withdrawals)
from stations.scenario import ScenarioError

T = np.arange(10, dtype=float)
PL = np.full(10, 1.0)


def series(err_at=None, err=0.1, avail=None):
    e = np.full(10, 0.05)
    if err_at is not None:
        e[err_at] = err
    a = np.ones(10, bool) if avail is None else np.asarray(avail, bool)
    return e, a


def test_alarm_before_the_error_is_an_alarm_with_its_time():
    e, a = series(err_at=slice(6, 8), err=5.0)
    a[5:] = False  # withdrawn at 5, the error comes later
    out = fault_outcome(T, e, PL, a, withdrawals(a), 4.0, 9.0)
    assert out == {"outcome": "alarm", "tta_train_s": 1.0, "hmi_epochs": 0}


def test_error_beyond_the_pl_while_available_is_a_missed_alarm():
    e, a = series(err_at=slice(5, 7), err=5.0)
    out = fault_outcome(T, e, PL, a, withdrawals(a), 4.0, 9.0)
    assert out["outcome"] == "missed" and out["hmi_epochs"] == 2 and out["tta_train_s"] is None
    a[6:] = False  # the alarm comes, one epoch too late
    out = fault_outcome(T, e, PL, a, withdrawals(a), 4.0, 9.0)
    assert out["outcome"] == "missed" and out["hmi_epochs"] == 1


def test_protected_and_unavailable():
    e, a = series(err_at=5, err=0.9)  # grows, stays inside its PL
    assert fault_outcome(T, e, PL, a, withdrawals(a), 4.0, 9.0)["outcome"] == "protected"
    a[:] = False
    assert fault_outcome(T, e, PL, a, withdrawals(a), 4.0, 9.0)["outcome"] == "unavailable"


def test_method_figures_count_every_epoch():
    e, a = series(err_at=3, err=2.0)
    a[7:] = False
    f = method_figures(e, PL, a, withdrawals(a))
    assert (f["epochs"], f["available"], f["hmi"], f["alarms"]) == (10, 7, 1, 1)
    assert f["hmi_beyond_alert_limit"] == 1  # 2 m > the 1.7 m along-track alert limit
    assert method_figures(e, PL, a, withdrawals(a), alert_limit_m=2.5)["hmi_beyond_alert_limit"] == 0
    assert f["availability"] == pytest.approx(0.7)


@pytest.mark.slow  # builds a world per auto-satellite fault (~10 s)
def test_shipped_campaign_covers_every_fault_kind_on_two_lines():
    from stations.scenario import FAULT_KINDS

    pairs = expand(load_campaign("issue15"))
    assert len(pairs) >= 10
    assert {f.kind for p in pairs for f in p.scenario.faults} == set(FAULT_KINDS)
    assert len({p.scenario.line.id for p in pairs}) >= 2
    assert any(b.kind == "tunnel" for p in pairs for b in p.scenario.line.blockages)
    assert {p.scenario.errors.ionosphere.level for p in pairs} >= {"quiet", "moderate", "active", "storm"}
    assert {p.scenario.rail for p in pairs} == {"dry", "wet"}
    assert all(f.satellite != "auto" for p in pairs for f in p.scenario.faults)


def test_unknown_campaign_refused():
    with pytest.raises(ScenarioError, match="no such file"):
        load_campaign("no-such-campaign")


def test_cli_refuses_an_unknown_campaign(tmp_path):
    from typer.testing import CliRunner

    from augnet.scenario.cli import app

    res = CliRunner().invoke(app, ["campaign", "no-such-campaign", "--out", str(tmp_path / "out")])
    assert res.exit_code == 2 and "no such file" in res.output
