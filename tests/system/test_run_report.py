"""The run report (`augnet-run-report.json`) from a fixed set of counters: every key and value."""

from __future__ import annotations

import collections
import json
from types import SimpleNamespace as NS

from augnet.system.run_report import run_report
from augnet.system.trains import TrainStats

STARTED_UNIX, ENDED_UNIX = 1_795_000_000.25, 1_795_000_240.31


def _centre():
    return NS(stations=["STA2", "STA1", "OFF1"], timings=NS(epochs=231), solve_ms_p99=lambda: 41.25,
              latency_ms_p99=lambda: {"vrs_ready_ms_p99": 80.1, "vrs_sent_ms_p99": 95.3},
              stages_ms=lambda: {"epochs": 200, "sessions": 2, "planned_ahead": 0.5,
                                 "synthesis": {"p50": 1.0, "p90": 2.0, "p99": 3.0}},
              errors=0, restarts=1)


def _trains():
    fixed = TrainStats(epochs=230, by_status=collections.Counter({"fix": 200, "float": 25, "single": 5}),
                       first_fix_s=31.0, vrs_epochs=220, base_resets=1, base_moves=3,
                       balises=[NS(balise_id="B1"), NS(balise_id="B2")], errors=0)
    fixed.correction_latency_s.extend([0.1, 0.2, 0.3, 0.25, float("nan")])
    fixed.along_pl_m.extend([0.04, 0.05, 0.06, float("inf")])
    fixed.cross_pl_m.extend([0.05, 0.06, 0.07, float("inf")])
    fixed.correction_along_m.extend([0.0, 0.0, 0.0, float("inf")])
    return {"G101": NS(id="G101", stats=fixed, last=NS(solution=NS(status=1))),
            "G303": NS(id="G303", stats=TrainStats(), last=None)}


ALARMS = [{"kind": "station-down", "subject": "STA4", "severity": "warning", "message": "silent",
           "at_utc": "2026-12-01T00:00:00+00:00"}]
RBC = {"link_up": True, "rbc_fresh": True, "sections": 5, "rbc_alarms": 0}
CASTER = {"port": 2101, "counters": {"requests": 10, "rejected": 1},
          "mounts": {"VRS": {"bytes_in": 0, "bytes_out": 5000, "clients_total": 2, "kind": "vrs"},
                     "STA1": {"bytes_in": 900, "bytes_out": 0, "clients_total": 0, "extra": 1}}}

EXPECTED = {
    "scenario": "demo", "started_utc": "2026-11-18T11:06:40.250000+00:00", "duration_s": 240.1,
    "stations": ["OFF1", "STA1", "STA2"], "network_epochs": 231, "centre_solve_ms_p99": 41.25,
    "centre_latency": {"vrs_ready_ms_p99": 80.1, "vrs_sent_ms_p99": 95.3},
    "centre_stages_ms": {"epochs": 200, "sessions": 2, "planned_ahead": 0.5,
                         "synthesis": {"p50": 1.0, "p90": 2.0, "p99": 3.0}},
    "centre_errors": 0, "centre_restarts": 1,
    "trains": {
        "G101": {"epochs": 230, "status_counts": {"fix": 200, "float": 25, "single": 5}, "fix_rate": 0.8696,
                 "time_to_first_fix_s": 31.0, "vrs_epochs": 220, "correction_latency_p50_s": 0.225,
                 "correction_latency_p99_s": 0.298, "base_moves": 3, "base_resets": 1, "balises": ["B1", "B2"],
                 "errors": 0, "holds_fix": True, "along_pl_p50_m": 0.05, "cross_pl_p50_m": 0.06,
                 "correction_along_p50_m": 0.0, "unbounded_epochs": 1},
        "G303": {"epochs": 0, "status_counts": {}, "fix_rate": 0.0, "time_to_first_fix_s": None, "vrs_epochs": 0,
                 "correction_latency_p50_s": None, "correction_latency_p99_s": None, "base_moves": 0,
                 "base_resets": 0, "balises": [], "errors": 0, "holds_fix": False, "along_pl_p50_m": None,
                 "cross_pl_p50_m": None, "correction_along_p50_m": None, "unbounded_epochs": 0},
    },
    "alarms": ALARMS, "rbc": RBC,
    "caster": {"port": 2101, "counters": {"requests": 10, "rejected": 1},
               "mounts": {"VRS": {"bytes_in": 0, "bytes_out": 5000, "clients_total": 2},
                          "STA1": {"bytes_in": 900, "bytes_out": 0, "clients_total": 0}}},
    "store": {"writes": 17, "failures": 0}, "sections": {},  # filled by the System (section register)
}


def test_the_report_of_a_run_lists_every_counter_under_its_key():
    report = run_report("demo", STARTED_UNIX, ENDED_UNIX, centre=_centre(), trains=_trains(), alarms=ALARMS,
                        rbc_snapshot=RBC, caster_snapshot=CASTER, store_counts={"writes": 17, "failures": 0})
    text = report.to_json()
    assert json.loads(text) == EXPECTED
    assert list(json.loads(text)) == list(EXPECTED)  # the file's key order
    assert list(json.loads(text)["trains"]["G101"]) == list(EXPECTED["trains"]["G101"])


def test_a_run_that_never_started_its_parts_reports_empty_sections():
    report = json.loads(run_report("demo", STARTED_UNIX, ENDED_UNIX).to_json())
    assert report == {"scenario": "demo", "started_utc": "2026-11-18T11:06:40.250000+00:00", "duration_s": 240.1,
                      "stations": [], "network_epochs": 0, "centre_solve_ms_p99": None, "centre_latency": {},
                      "centre_stages_ms": {}, "centre_errors": 0, "centre_restarts": 0, "trains": {}, "alarms": [],
                      "rbc": {}, "caster": {}, "store": {}, "sections": {}}


def test_the_timers_passages_are_reported_with_their_error_against_the_truth():
    from augnet.onboard.balise_timer import BaliseGroup, Miss, Passage
    from augnet.system.run_report import timed_balise_entry

    g1, g2 = BaliseGroup("VB-1", "L1-2", 156000.0), BaliseGroup("VB-2", "L1-2", 151000.0)
    sink = NS(passages=[Passage(g1, 100.0, 100.004, -1, 83.3, 0.058)], misses=[Miss(g2, 160.2, "estimate too old")],
              brakes=[(161.0, "2 consecutive linked groups missed")])
    # the truth: 4 cm short of the group at the predicted moment, travelling towards decreasing chainage
    entry = timed_balise_entry(sink, "G303", lambda tid, t: 156000.04 if (tid, t) == ("G303", 100.0) else None)
    assert entry == {
        "passages": [{"group": "VB-1", "time_gpst": 100.0, "emitted_at_gpst": 100.004, "confidence_m": 0.058,
                      "speed_mps": 83.3, "error_m": -0.04}],
        "misses": [{"group": "VB-2", "time_gpst": 160.2, "reason": "estimate too old"}],
        "service_brake_requests": [{"time_gpst": 161.0, "reason": "2 consecutive linked groups missed"}],
        "max_abs_error_m": 0.04}
    assert timed_balise_entry(sink, "G303")["passages"][0]["error_m"] is None  # no truth given: none claimed
