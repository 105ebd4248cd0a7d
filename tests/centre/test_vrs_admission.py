"""The VRS admission policy on stepped sequences of corrected satellite sets (no simulation): when the moments
come, what the VRS carries between them, satellites leaving, and the `augnet vrs` flags (decision 0160)."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from augnet.centre.postprocess import network_satellites
from augnet.centre.vrs_admission import AdmissionConfig, AdmissionPolicy, check_config
from augnet.options import OptionError

STEP_S = 2.0
CFG = AdmissionConfig(interval_s=600.0, settle_s=30.0, min_satellites=10, max_wait_s=120.0)


def _g(*prns) -> set[str]:
    return {f"G{p:02d}" for p in prns}


def _run(policy, schedule, until_s):
    """Step the policy every STEP_S; `schedule` is [(from t, corrected set)]. Returns [(t, Admission)]."""
    out = []
    t = 0.0
    while t <= until_s:
        corrected = [c for t0, c in schedule if t0 <= t][-1]
        out.append((t, policy.step(t, corrected)))
        t += STEP_S
    return out


def test_entering_waits_for_the_set_to_settle_then_restarts_once():
    # the network fixes G1-G6 at 100 s (a network epoch: 5 DD), G7 at 110 s, then nothing changes
    sched = [(0.0, set()), (100.0, _g(1, 2, 3, 4, 5, 6)), (110.0, _g(*range(1, 8)))]
    out = _run(AdmissionPolicy(CFG, network_satellites), sched, 300.0)
    moments = [t for t, a in out if a.restart]
    assert moments == [140.0]  # 30 s after the last change
    for t, a in out:
        assert a.carried == (frozenset(_g(*range(1, 8))) if t >= 140.0 else frozenset())
        if 100.0 <= t < 140.0:
            assert a.waiting == {s for s in [c for t0, c in sched if t0 <= t][-1]}


def test_entering_at_once_with_min_satellites_corrected():
    sched = [(0.0, set()), (50.0, _g(*range(1, 11))), (60.0, _g(*range(1, 12)))]
    out = _run(AdmissionPolicy(CFG, network_satellites), sched, 200.0)
    assert [t for t, a in out if a.restart] == [50.0]
    assert out[-1][1].carried == frozenset(_g(*range(1, 11)))  # G11 waits for the next moment
    assert out[-1][1].waiting == frozenset(_g(11))


def test_new_satellites_wait_for_the_interval_and_enter_together():
    base = _g(*range(1, 11))
    sched = [(0.0, base), (200.0, base | _g(11)), (300.0, base | _g(11, 12)), (640.0, base | _g(11, 12, 13))]
    out = _run(AdmissionPolicy(CFG, network_satellites), sched, 900.0)
    moments = [t for t, a in out if a.restart]
    # 0 s: entering (10 corrected); G11 and G12 wait for the interval (the set has settled by then), G13 for the
    # next one
    assert moments == [0.0, 600.0]
    by_t = dict(out)
    assert by_t[598.0].carried == base and by_t[598.0].waiting == _g(11, 12)
    assert by_t[600.0].carried == base | _g(11, 12) and not by_t[600.0].waiting
    assert by_t[900.0].carried == base | _g(11, 12) and by_t[900.0].waiting == _g(13)


def test_max_wait_when_the_set_never_settles():
    base = _g(*range(1, 11))
    # after 500 s a satellite rises every 20 s: never 30 s unchanged
    sched = [(0.0, base)] + [(500.0 + 20.0 * k, base | _g(*range(11, 12 + k))) for k in range(15)]
    cfg = AdmissionConfig(interval_s=600.0, settle_s=30.0, min_satellites=20, max_wait_s=150.0)
    out = _run(AdmissionPolicy(cfg, network_satellites), sched, 800.0)
    # entering once G1-G10 settled (30 s); then the interval is over at 630 s, G11 has waited 150 s at 650 s
    assert [t for t, a in out if a.restart] == [30.0, 650.0]


def test_min_satellites_waiting_make_a_moment_before_the_set_settles():
    base = _g(*range(1, 7))
    sched = [(0.0, base)] + [(610.0 + 4.0 * k, base | _g(*range(7, 8 + k))) for k in range(12)]
    cfg = AdmissionConfig(interval_s=600.0, settle_s=30.0, min_satellites=4, max_wait_s=300.0)
    out = _run(AdmissionPolicy(cfg, network_satellites), sched, 700.0)
    moments = [t for t, a in out if a.restart]
    assert moments[1] == 622.0  # G7-G10 waiting: 4
    assert dict(out)[622.0].carried == base | _g(7, 8, 9, 10)


def test_lost_satellites_leave_at_once_and_wait_when_back():
    base = _g(*range(1, 11))
    sched = [(0.0, base), (100.0, base - _g(3)), (150.0, base)]
    out = dict(_run(AdmissionPolicy(CFG, network_satellites), sched, 400.0))
    assert out[100.0].carried == base - _g(3) and not out[100.0].restart
    assert out[150.0].carried == base - _g(3) and out[150.0].waiting == _g(3)
    assert not any(a.restart for t, a in out.items() if t > 0.0)


def test_falling_below_a_network_epoch_admits_the_waiting_at_once():
    base = _g(1, 2, 3, 4, 5, 6)
    # G7 waits since 50 s; at 100 s G1 is lost: G2-G6 alone are 4 DD, with G7 they are 5
    sched = [(0.0, base), (50.0, base | _g(7)), (100.0, (base | _g(7)) - _g(1))]
    out = dict(_run(AdmissionPolicy(CFG, network_satellites), sched, 200.0))
    assert out[98.0].carried == base
    assert out[100.0].restart and out[100.0].carried == _g(2, 3, 4, 5, 6, 7)


def test_too_few_corrected_is_single_base_and_a_system_alone_is_left_out():
    sched = [(0.0, _g(*range(1, 11)) | {"E01"}), (100.0, _g(1, 2, 3, 4, 5))]
    out = dict(_run(AdmissionPolicy(CFG, network_satellites), sched, 200.0))
    assert out[0.0].carried == _g(*range(1, 11))  # one Galileo satellite forms no DD
    assert out[100.0].carried == frozenset()  # 4 DD: single-base


def test_a_master_change_is_a_moment_for_the_waiting():
    base = _g(*range(1, 11))
    policy = AdmissionPolicy(CFG, network_satellites)
    assert policy.step(0.0, base).restart
    assert policy.step(10.0, base | _g(11)).waiting == _g(11)
    policy.restart()  # the VRS changes master: every satellite restarts anyway
    a = policy.step(12.0, base | _g(11))
    assert a.restart and a.carried == base | _g(11)


def test_off_admits_every_satellite_when_corrected():
    policy = AdmissionPolicy(AdmissionConfig(admission=False), network_satellites)
    assert policy.step(0.0, _g(*range(1, 7))).carried == _g(*range(1, 7))
    a = policy.step(2.0, _g(*range(1, 8)))
    assert a.carried == _g(*range(1, 8)) and not a.restart


@pytest.mark.parametrize("field, value", [("interval_s", -1.0), ("settle_s", float("nan")), ("min_satellites", 0)])
def test_bad_settings_are_named(field, value):
    with pytest.raises(OptionError, match=field):
        check_config(AdmissionConfig(**{field: value}))


@pytest.mark.parametrize("args, words", [(["--admission", "maybe"], "--admission maybe"),
                                         (["--admission-interval-s", "-5"], "--admission-interval-s -5"),
                                         (["--admission-min-satellites", "x"], "--admission-min-satellites x")])
def test_vrs_flags_refuse_bad_values_by_name(tmp_path, args, words):
    from augnet.cli import _mount, app

    _mount()
    out = CliRunner().invoke(app, ["vrs", "--record", str(tmp_path), "--at", "0,0,0", "--out",
                                   str(tmp_path / "v.rnx"), *args])
    assert out.exit_code == 2
    assert words in out.stderr
