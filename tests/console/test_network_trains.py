"""Network status and trains, from the live state the running system writes (and the store's train records)."""

from __future__ import annotations

import math
import time

import pytest

from augnet.console.live import BaselineLive, StationLive, TrainLive
from augnet.store.models import Train, TrainSession


def _feed(live):
    live.set_line({"id": "L1", "length_km": 96.4, "polyline": [[30.0, 114.0], [30.0, 115.0]]})
    live.update_station(StationLive("STA1", 101, 30.0, 114.0, 20.0, along_km=0.0, up=True, satellites=22))
    live.update_station(StationLive("STA2", 102, 30.0, 114.5, 20.0, along_km=48.2, up=True, satellites=21))
    live.update_station(StationLive("STA3", 103, 30.0, 115.0, 20.0, along_km=96.4, up=False, satellites=0))
    live.set_baselines([BaselineLive("STA1", "STA2", 48.2, "fixed", 0.97, 1.1),
                        BaselineLive("STA2", "STA3", 48.2, "none", 0.0, None)])
    live.set_network({"epoch_gpst": "2026-11-22T02:00:00", "master": "STA2", "model": "linear", "quality": "ok",
                      "excluded_satellites": ["G12"], "correction_age_p99_s": 1.4})


def test_network_summary(console):
    c = console
    empty = c.client.get("/api/network", headers=c.as_("vera")).json()
    assert empty["running"] is False and empty["baselines"] == [] and empty["stations_total"] == 0
    _feed(c.live)
    r = c.client.get("/api/network", headers=c.as_("vera"))
    assert r.status_code == 200
    n = r.json()
    assert n["running"] is True
    assert n["summary"]["master"] == "STA2" and n["summary"]["excluded_satellites"] == ["G12"]
    assert (n["stations_total"], n["stations_up"]) == (3, 2)
    assert n["baselines_by_state"] == {"fixed": 1, "float": 0, "none": 1}
    assert n["baselines"][0] == {"a": "STA1", "b": "STA2", "length_km": 48.2, "state": "fixed",
                                 "fixed_fraction": 0.97, "residual_rms_cm": 1.1}
    assert c.client.get("/api/network/baselines", headers=c.as_("vera")).json() == n["baselines"]
    line = c.client.get("/api/line", headers=c.as_("vera")).json()
    assert line == {"id": "L1", "length_km": 96.4, "polyline": [[30.0, 114.0], [30.0, 115.0]]}


def test_trains_live_fields_and_age(console):
    c = console
    now = time.time()
    c.live.update_train(TrainLive("T2", 30.0, 114.3, 21.0, "L1", 28.9, 0.4, "float", 2.5, 0.9, 1.8, 160.0, now - 3))
    c.live.update_train(TrainLive("T1", 30.0, 114.1, 21.0, "L1", 9.6, -0.1, "fix", 1.0, 0.12, 0.3, 250.0, now))
    r = c.client.get("/api/trains", headers=c.as_("vera"))
    assert r.status_code == 200
    trains = r.json()
    assert [t["id"] for t in trains] == ["T1", "T2"]
    t2 = trains[1]
    assert (t2["fix_state"], t2["along_km"], t2["cross_track_m"], t2["correction_age_s"], t2["hpl_m"],
            t2["vpl_m"], t2["speed_kmh"], t2["track_id"]) == ("float", 28.9, 0.4, 2.5, 0.9, 1.8, 160.0, "L1")
    assert 3.0 <= t2["age_s"] < 10.0


def test_non_finite_numbers_reach_the_client_as_null(sqlite_console):
    c = sqlite_console
    c.live.update_train(TrainLive("T1", 30.0, 114.1, 21.0, None, None, None, "single", math.inf, math.nan))
    t = c.client.get("/api/trains", headers=c.as_("vera")).json()[0]
    assert t["correction_age_s"] is None and t["hpl_m"] is None
    assert c.client.get("/api/live/snapshot", headers=c.as_("vera")).json()["trains"][0]["hpl_m"] is None


def test_train_detail_with_store_sessions(console):
    c = console
    c.live.update_train(TrainLive("T1", 30.0, 114.1, 21.0, "L1", 9.6, 0.0, "fix", 1.0, 0.1, 0.3, 250.0))
    with c.sessions.begin() as s:
        train = Train(code="T1", length_m=400.0)
        train.sessions.append(TrainSession(mountpoint="VRS", bytes_sent=12_345, fix_rate=0.98))
        s.add(train)
        s.add(Train(code="T9"))
    r = c.client.get("/api/trains/T1", headers=c.as_("vera"))
    assert r.status_code == 200
    d = r.json()
    assert d["registered"] is True and d["length_m"] == 400.0 and d["live"]["fix_state"] == "fix"
    assert [(x["mountpoint"], x["bytes_sent"], x["fix_rate"], x["ended_at"]) for x in d["sessions"]] == [
        ("VRS", 12_345, 0.98, None)]
    parked = c.client.get("/api/trains/T9", headers=c.as_("vera")).json()
    assert parked["live"] is None and parked["registered"] is True and parked["sessions"] == []
    assert c.client.get("/api/trains/T404", headers=c.as_("vera")).status_code == 404


@pytest.mark.parametrize("route", ["/api/network", "/api/trains", "/api/line", "/api/network/baselines"])
def test_live_routes_need_a_token(sqlite_console, route):
    assert sqlite_console.client.get(route).status_code == 401
