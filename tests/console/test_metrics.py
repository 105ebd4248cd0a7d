"""`/metrics`: Prometheus text format, request counts and latency per route template, system gauges."""

from __future__ import annotations

import re

from augnet.console.live import BaselineLive, StationLive, TrainLive
from augnet.console.metrics import CONTENT_TYPE, LATENCY_BUCKETS_S, RouteLabels, escape_label
from augnet.store import queries as q
from augnet.store.models import Severity

# One sample line of the text exposition format 0.0.4: name, optional {labels}, value.
SAMPLE = re.compile(r'^([a-zA-Z_:][a-zA-Z0-9_:]*)(\{(?:[a-zA-Z_][a-zA-Z0-9_]*="(?:[^"\\]|\\.)*",?)*\})? '
                    r'(-?[0-9.eE+-]+|\+Inf|NaN)$')
LABEL = re.compile(r'([a-zA-Z_][a-zA-Z0-9_]*)="((?:[^"\\]|\\.)*)"')


def parse(text: str) -> dict[tuple[str, frozenset], float]:
    """Every line is a comment or a valid sample; every sample's family has a TYPE line."""
    typed, samples = set(), {}
    for line in text.splitlines():
        if line.startswith("# TYPE "):
            typed.add(line.split()[2])
            continue
        if line.startswith("#"):
            continue
        m = SAMPLE.match(line)
        assert m, f"not a Prometheus sample: {line!r}"
        name = m.group(1)
        family = re.sub(r"_(bucket|sum|count)$", "", name)
        assert name in typed or family in typed, f"no TYPE for {name}"
        labels = frozenset(LABEL.findall(m.group(2) or ""))
        samples[(name, labels)] = float(m.group(3))
    return samples


def value(samples, name, **labels):
    return samples[(name, frozenset((k, str(v)) for k, v in labels.items()))]


def test_metrics_format_and_request_counts(console):
    c = console
    for _ in range(3):
        assert c.client.get("/api/trains", headers=c.as_("vera")).status_code == 200
    c.client.get("/api/trains")  # 401
    c.client.get("/api/alarms/17", headers=c.as_("vera"))  # 404, labelled by template
    c.client.get("/no/such/page")
    r = c.client.get("/metrics")
    assert r.status_code == 200 and r.headers["content-type"] == CONTENT_TYPE
    s = parse(r.text)
    assert value(s, "augnet_console_requests_total", method="GET", route="/api/trains", status=200) == 3
    assert value(s, "augnet_console_requests_total", method="GET", route="/api/trains", status=401) == 1
    assert value(s, "augnet_console_requests_total", method="GET", route="/api/alarms/{alarm_id}", status=404) == 1
    assert value(s, "augnet_console_requests_total", method="GET", route="unmatched", status=404) == 1
    # histogram: cumulative buckets, +Inf equals the count
    buckets = [value(s, "augnet_console_request_duration_seconds_bucket", method="GET", route="/api/trains", le=le)
               for le in [*LATENCY_BUCKETS_S, "+Inf"]]
    assert buckets == sorted(buckets) and buckets[-1] == 4
    assert value(s, "augnet_console_request_duration_seconds_count", method="GET", route="/api/trains") == 4
    assert value(s, "augnet_console_request_duration_seconds_sum", method="GET", route="/api/trains") > 0


def test_metrics_system_gauges(console):
    c = console
    c.live.update_train(TrainLive("T1", 30, 114, 20, "L1", 1.0, 0.0, "fix", 1.5, 0.2, 0.4, 100.0))
    c.live.update_train(TrainLive("T2", 30, 114, 20, "L1", 2.0, 0.0, "float", 4.5, 1.2, 2.4, 100.0))
    c.live.update_train(TrainLive("T3", 30, 114, 20, "L1", 3.0, 0.0, "fix", None, None, None, None))
    c.live.update_station(StationLive("STA1", 1, 30, 114, 20, up=True))
    c.live.update_station(StationLive("STA2", 2, 30, 114, 20, up=False))
    c.live.update_station(StationLive("STA3", 3, 30, 114, 20, up=True, enabled=False))
    c.live.set_baselines([BaselineLive("STA1", "STA2", 40.0, "fixed", 1.0), BaselineLive("STA2", "STA3", 40.0,
                                                                                         "float", 0.3)])
    with c.sessions.begin() as s:
        q.raise_alarm(s, "station-down", "STA2", Severity.CRITICAL)
        q.raise_alarm(s, "satellite-excluded", "G12", Severity.WARNING)
        a = q.raise_alarm(s, "satellite-excluded", "C07", Severity.WARNING)
        s.flush()
        q.acknowledge_alarm(s, "otto", a.id)
    s = parse(c.client.get("/metrics").text)
    assert value(s, "augnet_trains", fix_state="fix") == 2 and value(s, "augnet_trains", fix_state="float") == 1
    assert value(s, "augnet_trains", fix_state="none") == 0
    assert value(s, "augnet_train_correction_age_seconds_max") == 4.5
    assert value(s, "augnet_train_hpl_meters_max") == 1.2
    assert value(s, "augnet_stations", state="up") == 1 and value(s, "augnet_stations", state="down") == 1
    assert value(s, "augnet_stations", state="disabled") == 1
    assert value(s, "augnet_baselines", state="fixed") == 1 and value(s, "augnet_baselines", state="none") == 0
    assert value(s, "augnet_alarms_open", state="raised", severity="critical") == 1
    assert value(s, "augnet_alarms_open", state="raised", severity="warning") == 1
    assert value(s, "augnet_alarms_open", state="acknowledged", severity="warning") == 1
    assert value(s, "augnet_alarms_open", state="raised", severity="info") == 0
    assert value(s, "augnet_console_live_events_total") == 7  # 3 trains, 3 stations, 1 baseline set
    assert ("augnet_caster_clients", frozenset()) not in s  # no caster in this process


def test_metrics_with_caster_snapshot(sqlite_console):
    c = sqlite_console
    c.live.caster_snapshot = lambda: {"clients_now": 7, "mounts": {'A"B': {"bytes_out": 10}, "VRS": {"bytes_out": 99}}}
    s = parse(c.client.get("/metrics").text)
    assert value(s, "augnet_caster_clients") == 7
    assert value(s, "augnet_caster_mount_bytes_out_total", mount='A\\"B') == 10  # escaped per the format
    assert value(s, "augnet_caster_mount_bytes_out_total", mount="VRS") == 99
    assert value(s, "augnet_caster_logins_total", outcome="failed") == 0 and value(s, "augnet_caster_auth_alarm") == 0


def test_metrics_show_a_real_casters_counters(sqlite_console):
    """Against a running caster: a wrong password, a throttled guesser, a good login, a source's bytes."""
    from augwire.chunked import encode_chunk
    from augwire.passwords import hash_password
    from ntrip_caster.auth import User
    from ntrip_caster.config import CasterConfig, Limits, MountConfig
    from ntrip_caster.embedded import CasterThread
    from ntrip_caster.throttle import FREE_FAILURES
    from tests.ntrip.helpers import FAST, open_client, open_v2_source, read_all, wait_for

    users = {"train1": User("train1", hash_password("train-pw", **FAST), frozenset({"trains"})),
             "station1": User("station1", hash_password("station-pw", **FAST), frozenset({"stations"}))}
    mounts = (MountConfig("BASE01", "source", frozenset({"trains"}), frozenset({"stations"})),)
    config = CasterConfig(host="127.0.0.1", port=0, limits=Limits(), users=users, mounts=mounts)
    with CasterThread(config, use_uvloop=False) as ct:
        c = sqlite_console
        c.live.caster_snapshot = ct.snapshot
        src = open_v2_source(ct.port, "BASE01", "station1", "station-pw")
        try:
            wait_for(lambda: ct.snapshot()["mounts"]["BASE01"]["live"])
            src.sendall(encode_chunk(b"\xd3\x00\x00\x47\xea\x4b"))  # an empty RTCM frame
            ct.caster.clock = lambda: 1000.0  # the throttle's clock stands still: its lock does not expire
            for _ in range(FREE_FAILURES + 2):  # past the free failures the next ones are refused unhashed
                sock, _head = open_client(ct.port, "BASE01", version=2, user="train1", password="wrong")
                read_all(sock)
                sock.close()
            wait_for(lambda: ct.snapshot()["mounts"]["BASE01"]["bytes_in"] > 0)
            s = parse(c.client.get("/metrics").text)
        finally:
            src.close()
    assert value(s, "augnet_caster_logins_total", outcome="failed") == FREE_FAILURES
    assert value(s, "augnet_caster_logins_total", outcome="throttled") == 2
    assert value(s, "augnet_caster_logins_total", outcome="succeeded") == 1  # the station's
    assert value(s, "augnet_caster_responses_total", status="401") == FREE_FAILURES
    assert value(s, "augnet_caster_responses_total", status="429") == 2
    assert value(s, "augnet_caster_connections") >= 1 and value(s, "augnet_caster_clients") == 0
    assert value(s, "augnet_caster_mount_bytes_in_total", mount="BASE01") > 0


def test_route_labels_and_escaping():
    labels = RouteLabels(["/api/alarms", "/api/alarms/{alarm_id}", "/api/alarms/{alarm_id}/acknowledge"],
                         mounts=("/static",))
    assert labels("/api/alarms/5/acknowledge") == "/api/alarms/{alarm_id}/acknowledge"
    assert labels("/api/alarms/5/6") == "unmatched"
    assert labels("/static/console.js") == "/static/{path}"
    assert escape_label('a\\b"c\nd') == 'a\\\\b\\"c\\nd'
