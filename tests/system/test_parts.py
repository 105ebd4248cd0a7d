"""The parts of `augnet up` that are pure functions: settings, the run's scenario, RSSP-I line sections."""

from __future__ import annotations

import pytest

from augnet.system.rbc_link import SECTION_LENGTH_KM, SectionPlan, fixed_stations
from augnet.system.run_config import scenario_for_run
from augnet.system.settings import MAX_LIVE_TRAINS, SettingsError, SystemSettings
from rssp1.messages import SectionStatus
from stations.track import TrackLine


@pytest.mark.parametrize("kwargs, field", [
    ({"trains": MAX_LIVE_TRAINS + 1}, "trains"), ({"trains": -1}, "trains"),
    ({"duration_s": 0.0}, "duration"), ({"caster_port": 70000}, "caster-port"),
    ({"caster_port": 9000, "console_port": 9000}, "console-port"), ({"db_url": "augnet.db"}, "db"),
    ({"bus_url": "redis://x"}, "bus"),
])
def test_an_invalid_setting_is_named(kwargs, field):
    with pytest.raises(SettingsError) as err:
        SystemSettings(**kwargs).validate()
    assert err.value.field == field
    assert str(err.value).startswith(field)


def test_the_run_starts_a_moment_from_now_with_the_requested_trains():
    now = 1_479_350_000.0
    sc = scenario_for_run(SystemSettings(trains=6, duration_s=60), now_gpst=now)
    from augnet.gnss import time as gtime
    t0 = gtime.from_datetime(sc.start)
    assert now < t0 <= now + 5 and t0 == int(t0)
    assert sc.duration_s >= 60
    ids = [t.id for t in sc.trains]
    assert ids[:2] == ["G101", "G303"] and len(set(ids)) == 6
    length_km = TrackLine(sc.line).length_m / 1000.0
    assert all(0 <= t.start_km <= length_km for t in sc.trains)
    assert [t.id for t in scenario_for_run(SystemSettings(trains=1), now_gpst=now).trains] == ["G101"]
    assert scenario_for_run(SystemSettings(trains=0), now_gpst=now).trains == []


def test_line_sections_follow_the_stations_that_bracket_them():
    plan = SectionPlan(45.0, {"A": 2.0, "B": 22.0, "C": 44.0})
    assert plan.ids == [1, 2, 3, 4, 5] and SECTION_LENGTH_KM == 10.0
    assert plan.bracket[1] == ("A", "B") and plan.bracket[3] == ("B", "C")
    all_up = plan.statuses({"A", "B", "C"}, {"A", "B", "C"})
    assert set(all_up.values()) == {SectionStatus.OK}
    b_down = plan.statuses({"A", "C"}, {"A", "C"})
    assert b_down[1] == b_down[3] == SectionStatus.DEGRADED  # interpolation over a longer distance
    float_net = plan.statuses({"A", "B", "C"}, set())
    assert set(float_net.values()) == {SectionStatus.DEGRADED}
    assert set(plan.statuses(set(), set()).values()) == {SectionStatus.DO_NOT_USE}
    assert fixed_stations({"A-B": 0.9, "B-C": 0.2}) == {"A", "B"}


def test_a_new_station_is_registered_enabled_and_an_operators_decision_stands(tmp_path):
    """A fresh store once reported every new station disabled (the column default is applied at the
    INSERT), so `augnet up` ignored all station data for its first seconds and lost the orbits."""
    from augnet.store.db import open_store
    from augnet.system import persistence
    from augnet.store import queries

    sessions = open_store(f"sqlite:///{tmp_path / 'augnet.db'}")
    xyz = (-2.2e6, 4.4e6, 4.0e6)
    with sessions.begin() as s:
        assert persistence.register_station(s, "STA1", "STA1", xyz, 101, "STA1") is True
    with sessions.begin() as s:
        queries.update_station(s, "op", "STA1", enabled=False)
    with sessions.begin() as s:
        assert persistence.register_station(s, "STA1", "STA1", xyz, 101, "STA1") is False
        assert persistence.station_records(s)["STA1"].enabled is False


def test_the_scenario_seeds_only_an_empty_station_table(tmp_path):
    """A station an operator deleted does not come back with the next run's scenario (issue 19)."""
    from types import SimpleNamespace

    import numpy as np

    from augnet.store import queries
    from augnet.store.db import open_store
    from augnet.system import persistence
    from augnet.system.run_config import register_run
    from ntrip_caster.config import CasterConfig

    sessions = open_store(f"sqlite:///{tmp_path / 'augnet.db'}")
    rx = [SimpleNamespace(id=f"STA{k}", ecef=np.array([[4.8e6 + 1e4 * k, 1.7e5, 4.2e6]]), rtcm_id=100 + k)
          for k in (1, 2)]
    cfg = CasterConfig(users={}, mounts=())
    with sessions.begin() as s:
        records, _ = register_run(s, rx, cfg, {})
    assert sorted(records) == ["STA1", "STA2"] and records["STA2"].xyz_m == (4.82e6, 1.7e5, 4.2e6)
    with sessions.begin() as s:
        queries.delete_station(s, "admin", "STA2")
    with sessions.begin() as s:
        records, _ = register_run(s, rx, cfg, {})
    assert sorted(records) == ["STA1"]
    with sessions.begin() as s:
        queries.delete_station(s, "admin", "STA1")
    with sessions.begin() as s:
        records, _ = register_run(s, rx, cfg, {})
    assert records == {}  # an operator emptied the registry: the scenario does not refill it


def test_load_test_trains_report_their_positions_spread_over_the_interval():
    """Independent trains do not all send their GGA in the same millisecond (which would move every VRS
    point at once and stall the load test's own loop while it stamps arrivals)."""
    import numpy as np

    from augnet.system.loadtest import GGA_INTERVAL_S, LinePoints, train_specs

    line = LinePoints([[39.0, 116.0, 0.0], [39.5, 116.5, 0.0]], 70_000.0)
    specs = train_specs("127.0.0.1", 2101, "VRS", 1000, "train", "pw", line)
    phases = np.array([t.gga_phase_s for t in specs])
    assert phases.min() >= 0.0 and phases.max() < GGA_INTERVAL_S
    counts, _ = np.histogram(phases, bins=10, range=(0.0, GGA_INTERVAL_S))
    assert counts.min() >= 90 and counts.max() <= 110  # about 100 trains in every tenth of the interval
