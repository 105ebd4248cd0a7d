"""What `augnet up` tells is what happens (issue 19): the sourcetable advertises the systems the streams
carry, the epoch labelled UTC is UTC, a VRS mountpoint counts the bytes its clients got, a train without
corrections shows no correction age, and the RBC's own alarms reach the alarm store."""

from __future__ import annotations

import datetime as dt
import time
from types import SimpleNamespace as NS

import numpy as np
import pytest

from augnet.gnss import time as gtime
from augnet.gnss.geometry import geodetic_deg_to_ecef
from augnet.onboard.rtk import Status
from augnet.system.rbc_link import RbcConnection, SectionPlan
from augnet.system.run_config import caster_config, nav_system
from augnet.system.settings import SystemSettings
from augnet.system.trains import OnboardTrain
from ntrip_caster.config import MountConfig
from ntrip_caster.embedded import CasterThread
from ntrip_caster.gga import format_gga
from rssp1.messages import AlarmCode
from stations.scenario import load_scenario
from tests.ntrip.helpers import make_config, open_client, read_exactly
from tests.system.test_live_state import _centre, _epoch, _publisher


def test_sourcetable_advertises_the_scenarios_systems_only():
    sc = load_scenario("demo")
    assert "GLO" not in nav_system(sc) and nav_system(sc).split("+") == [
        {"G": "GPS", "E": "GAL", "C": "BDS"}[s] for s in sc.constellations]
    stations = [NS(id="S1", ecef=np.array([geodetic_deg_to_ecef(30.0, 114.0, 20.0)]))]
    trains = [NS(id="T1")]
    cfg = caster_config(SystemSettings(), sc, stations, trains, {"stations": "h", "train": "h"})
    for m in cfg.mounts:
        line = m.str_record().to_line()
        assert line.split(";")[6] == nav_system(sc), line  # STR field 7: nav-system


def test_epoch_utc_is_utc_not_gps_time():
    pub = _publisher()
    r = _epoch()
    pub.record_epoch(r)
    pub.publish_network(r, _centre(), None)
    utc = dt.datetime.fromisoformat(pub.live.network["epoch_utc"])
    assert utc.tzinfo is not None
    leap = gtime.leap_seconds_at_gpst(r.t_gpst)
    assert leap == 18
    assert utc == gtime.to_datetime(r.t_gpst - leap).replace(tzinfo=dt.timezone.utc)
    assert abs((dt.datetime.now(dt.timezone.utc) - utc).total_seconds() - 1.0) < 5.0  # the epoch is ~1 s old


class _SendingFactory:
    """Sends a fixed block to each client at once (a stand-in for the centre)."""

    BLOCK = b"\xd3" + b"x" * 99

    def open(self, client_id, mount, fix, sink):
        sink(self.BLOCK)
        return NS(update_position=lambda fix: None, close=lambda: None)


@pytest.mark.parametrize("version", [1, 2])
def test_vrs_mountpoint_counts_the_bytes_its_clients_got(version):
    vrs = MountConfig("VRS", "vrs", frozenset({"trains"}), factory="unused:unused")
    with CasterThread(make_config(extra_mounts=(vrs,)), {"VRS": _SendingFactory()}) as ct:
        c, head = open_client(ct.port, "VRS", version=version, gga=format_gga(31.0, 121.0))
        got = head.partition(b"\r\n\r\n" if version == 2 else b"\r\n")[2]
        want = len(_SendingFactory.BLOCK) + (len(b"64\r\n\r\n") if version == 2 else 0)
        got += read_exactly(c, want - len(got)) if len(got) < want else b""
        deadline = time.monotonic() + 5
        while ct.caster.snapshot()["mounts"]["VRS"]["bytes_out"] == 0 and time.monotonic() < deadline:
            time.sleep(0.02)
        snap = ct.caster.snapshot()
        assert snap["mounts"]["VRS"]["bytes_out"] == want == len(got)
        c.close()


def _train_with(status: Status, age_s: float, vrs_epochs: int) -> OnboardTrain:
    tr = OnboardTrain("T1", lambda: None, None, "127.0.0.1", 1, "VRS")
    tr.last = NS(solution=NS(status=status, age_s=age_s))
    tr.stats.vrs_epochs = vrs_epochs
    return tr


def test_train_correction_age_is_none_until_it_has_corrections():
    assert _train_with(Status.SINGLE, 0.0, 0).correction_age_s() is None
    assert _train_with(Status.SINGLE, 0.0, 12).correction_age_s() is None  # corrections came, none used
    assert _train_with(Status.FIX, float("nan"), 12).correction_age_s() is None
    assert _train_with(Status.FIX, 0.4, 12).correction_age_s() == 0.4
    assert _train_with(Status.FLOAT, 1.0, 12).correction_age_s() == 1.0


def test_rbc_watchdog_alarms_are_raised_and_cleared_in_the_alarm_store():
    conn = RbcConnection(SectionPlan(20.0, {"A": 0.0, "B": 20.0}), {"A": 1, "B": 2}, on_alarm=lambda *a: None)
    assert conn.rbc_alarm_events() == []
    conn.rbc._watchdog(AlarmCode.CORRECTION_STALE, True, "corrections 6000 ms old")
    (kind, subject, severity, message, cleared), = conn.rbc_alarm_events()
    assert (kind, subject, severity, cleared) == ("rbc-correction-stale", "rbc", "critical", False)
    assert "6000 ms" in message
    assert conn.rbc_alarm_events() == []  # once per episode
    conn.rbc._watchdog(AlarmCode.CORRECTION_STALE, False, "")
    assert [(e[0], e[4]) for e in conn.rbc_alarm_events()] == [("rbc-correction-stale", True)]
    conn.rbc._watchdog(AlarmCode.CORRECTION_STALE, True, "again")
    assert [(e[0], e[4]) for e in conn.rbc_alarm_events()] == [("rbc-correction-stale", False)]
