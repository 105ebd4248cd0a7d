"""`/metrics` in the Prometheus text exposition format (version 0.0.4), written by hand: a few counters and
one histogram do not need a client library.

Request timing is a plain ASGI middleware (no per-request task or body copy, unlike Starlette's
BaseHTTPMiddleware), labelled by route template (from the app's OpenAPI paths, so the label is the full path
whatever the framework's routing internals) so ids in paths do not multiply the series.
"""

from __future__ import annotations

import bisect
import re
import threading
import time
from collections import defaultdict
from typing import Any

from sqlalchemy.orm import Session

from augnet.console.live import BASELINE_STATES, FIX_STATES, LiveState
from augnet.store import queries as q
from augnet.store.models import AlarmState, Severity

CONTENT_TYPE = "text/plain; version=0.0.4; charset=utf-8"
# Upper bounds [s] of the console latency histogram, around the 50 ms p99 goal.
LATENCY_BUCKETS_S = (0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5)
UNMATCHED_ROUTE = "unmatched"  # 404s: one series, whatever the path
# The caster's login counters (ntrip_caster/server.py `counters`) by the outcome label they are shown under.
CASTER_LOGIN_OUTCOMES = (("succeeded", "auth_succeeded"), ("failed", "auth_failed"),
                         ("throttled", "auth_refused_throttled"), ("busy", "auth_refused_busy"))


def escape_label(value: str) -> str:
    return value.replace("\\", "\\\\").replace("\n", "\\n").replace('"', '\\"')


def labels(**kv: Any) -> str:
    if not kv:
        return ""
    return "{" + ",".join(f'{k}="{escape_label(str(v))}"' for k, v in kv.items()) + "}"


def number(v: float | int) -> str:
    if isinstance(v, bool):
        return "1" if v else "0"
    if isinstance(v, int):
        return str(v)
    return repr(float(v))


class RequestMetrics:
    """Counts and times HTTP requests per (method, route, status); thread-safe."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.count: dict[tuple[str, str, int], int] = defaultdict(int)
        self.buckets: dict[tuple[str, str], list[int]] = {}
        self.sum_s: dict[tuple[str, str], float] = defaultdict(float)

    def observe(self, method: str, route: str, status: int, seconds: float) -> None:
        i = bisect.bisect_left(LATENCY_BUCKETS_S, seconds)
        with self._lock:
            self.count[(method, route, status)] += 1
            b = self.buckets.get((method, route))
            if b is None:
                b = self.buckets[(method, route)] = [0] * (len(LATENCY_BUCKETS_S) + 1)
            b[i] += 1
            self.sum_s[(method, route)] += seconds

    def lines(self) -> list[str]:
        with self._lock:
            count = dict(self.count)
            buckets = {k: list(v) for k, v in self.buckets.items()}
            sums = dict(self.sum_s)
        out = ["# HELP augnet_console_requests_total HTTP requests answered by the console.",
               "# TYPE augnet_console_requests_total counter"]
        for (method, route, status), n in sorted(count.items()):
            out.append(f"augnet_console_requests_total{labels(method=method, route=route, status=status)} {n}")
        out += ["# HELP augnet_console_request_duration_seconds Time to answer an HTTP request.",
                "# TYPE augnet_console_request_duration_seconds histogram"]
        for (method, route), b in sorted(buckets.items()):
            cumulative = 0
            for le, n in zip(LATENCY_BUCKETS_S, b):
                cumulative += n
                out.append("augnet_console_request_duration_seconds_bucket"
                           f"{labels(method=method, route=route, le=le)} {cumulative}")
            cumulative += b[-1]
            out.append("augnet_console_request_duration_seconds_bucket"
                       f"{labels(method=method, route=route, le='+Inf')} {cumulative}")
            out.append(f"augnet_console_request_duration_seconds_sum{labels(method=method, route=route)} "
                       f"{number(sums[(method, route)])}")
            out.append(f"augnet_console_request_duration_seconds_count{labels(method=method, route=route)} "
                       f"{cumulative}")
        return out


class RouteLabels:
    """Request path -> route template ("/api/alarms/17/acknowledge" -> "/api/alarms/{alarm_id}/acknowledge")."""

    def __init__(self, templates: list[str], mounts: tuple[str, ...] = ()) -> None:
        self.mounts = mounts  # prefixes serving a whole tree, e.g. "/static"
        self.static = {t for t in templates if "{" not in t}
        self.patterns = [(re.compile("^" + re.sub(r"\\{[^/]+?\\}", "[^/]+", re.escape(t)) + "$"), t)
                         for t in templates if "{" in t]

    def __call__(self, path: str) -> str:
        if path in self.static:
            return path
        for pattern, template in self.patterns:
            if pattern.match(path):
                return template
        for prefix in self.mounts:
            if path.startswith(prefix + "/"):
                return prefix + "/{path}"
        return UNMATCHED_ROUTE


class MetricsMiddleware:
    """ASGI middleware feeding RequestMetrics."""

    def __init__(self, app, metrics: RequestMetrics, labels: RouteLabels | None = None) -> None:
        self.app = app
        self.metrics = metrics
        self.labels = labels

    def route_label(self, scope) -> str:
        if self.labels is None:
            app = scope.get("app")
            templates = list(app.openapi().get("paths", {})) if app is not None else []
            self.labels = RouteLabels(templates + ["/"], mounts=("/static",))
        return self.labels(scope.get("path", ""))

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        start = time.perf_counter()
        status_box = [500]

        async def send_wrapper(message) -> None:
            if message["type"] == "http.response.start":
                status_box[0] = message["status"]
            await send(message)

        try:
            await self.app(scope, receive, send_wrapper)
        finally:
            elapsed = time.perf_counter() - start
            self.metrics.observe(scope["method"], self.route_label(scope), status_box[0], elapsed)


def _gauge(out: list[str], name: str, help_text: str, samples: list[tuple[dict, float | int]]) -> None:
    out.append(f"# HELP {name} {help_text}")
    out.append(f"# TYPE {name} gauge")
    for lab, value in samples:
        out.append(f"{name}{labels(**lab)} {number(value)}")


def render(request_metrics: RequestMetrics, live: LiveState, session: Session,
           caster_snapshot: dict | None = None, logins=None) -> str:
    """The whole exposition: request metrics, the live system's state, open alarms, login outcomes
    (`logins`: augnet.console.throttle.Counters)."""
    out = request_metrics.lines()
    now = time.time()

    trains = live.train_list()
    by_fix = {s: 0 for s in FIX_STATES}
    for t in trains:
        by_fix[t.fix_state if t.fix_state in by_fix else "none"] += 1
    _gauge(out, "augnet_trains", "Trains reporting to the console, by solution state.",
           [({"fix_state": s}, n) for s, n in by_fix.items()])
    ages = [t.correction_age_s for t in trains if t.correction_age_s is not None]
    _gauge(out, "augnet_train_correction_age_seconds_max", "Oldest correction age among trains.",
           [({}, max(ages) if ages else 0.0)])
    hpls = [t.hpl_m for t in trains if t.hpl_m is not None]
    _gauge(out, "augnet_train_hpl_meters_max", "Largest horizontal protection level among trains.",
           [({}, max(hpls) if hpls else 0.0)])
    stale = [now - t.updated_unix for t in trains]
    _gauge(out, "augnet_train_update_age_seconds_max", "Longest time since a train's last update.",
           [({}, max(stale) if stale else 0.0)])

    stations = live.station_list()
    st = {"up": 0, "down": 0, "disabled": 0}
    for s in stations:
        st["disabled" if not s.enabled else "up" if s.up else "down"] += 1
    _gauge(out, "augnet_stations", "Reference stations known to the live system, by state.",
           [({"state": k}, n) for k, n in st.items()])

    baselines = live.baseline_list()
    bl = {s: 0 for s in BASELINE_STATES}
    for b in baselines:
        bl[b.state if b.state in bl else "none"] += 1
    _gauge(out, "augnet_baselines", "Network baselines, by ambiguity state.",
           [({"state": k}, n) for k, n in bl.items()])

    counts = q.open_alarm_counts(session)
    _gauge(out, "augnet_alarms_open", "Alarms not cleared, by state and severity.",
           [({"state": state.value, "severity": sev.value}, counts.get((state.value, sev.value), 0))
            for state in (AlarmState.RAISED, AlarmState.ACKNOWLEDGED) for sev in Severity])

    _gauge(out, "augnet_console_websocket_subscribers", "Live feed websocket clients connected.",
           [({}, live.subscriber_count)])
    out += ["# HELP augnet_console_live_events_total Live events published to websocket subscribers.",
            "# TYPE augnet_console_live_events_total counter",
            f"augnet_console_live_events_total {live.events_published}"]

    if logins is not None:  # a rising "failed" or "refused" is someone guessing passwords
        out += ["# HELP augnet_console_logins_total Console login attempts by outcome (refused: throttled, "
                "not verified).", "# TYPE augnet_console_logins_total counter"]
        out += [f"augnet_console_logins_total{labels(outcome=k)} {getattr(logins, k)}"
                for k in ("succeeded", "failed", "refused")]

    if caster_snapshot is not None:
        out += caster_lines(caster_snapshot)
    return "\n".join(out) + "\n"


def _counter(out: list[str], name: str, help_text: str, samples: list[tuple[dict, float | int]]) -> None:
    out.append(f"# HELP {name} {help_text}")
    out.append(f"# TYPE {name} counter")
    for lab, value in samples:
        out.append(f"{name}{labels(**lab)} {number(value)}")


def _count(value: Any) -> float | int:
    """A snapshot's number, or 0 for anything else (the snapshot is the caster's, read as given)."""
    return value if isinstance(value, (int, float)) and not isinstance(value, bool) else 0


def caster_lines(snap: dict) -> list[str]:
    """The caster's snapshot (`ntrip_caster.server.Caster.snapshot`) as metrics: clients and connections,
    NTRIP logins by outcome (a rising failed / throttled / busy is someone guessing passwords, issue 19),
    answers by status, clients dropped by reason (revoked: an operator's change, decision 0180), bytes per
    mountpoint."""
    out: list[str] = []
    counters = snap.get("counters") if isinstance(snap.get("counters"), dict) else {}
    _gauge(out, "augnet_caster_clients", "NTRIP clients connected to the caster.",
           [({}, _count(snap.get("clients_now", 0)))])
    _gauge(out, "augnet_caster_connections", "TCP connections open on the caster (clients, sources, pending).",
           [({}, _count(snap.get("connections_now", 0)))])
    _gauge(out, "augnet_caster_auth_alarm", "1 while the caster's failed-login alarm is raised.",
           [({}, 1 if snap.get("auth_alarm") else 0)])
    _counter(out, "augnet_caster_logins_total", "NTRIP credential checks by outcome (throttled and busy: "
             "refused without hashing).",
             [({"outcome": outcome}, _count(counters.get(key, 0))) for outcome, key in CASTER_LOGIN_OUTCOMES])
    _counter(out, "augnet_caster_responses_total", "NTRIP error answers by HTTP status.",
             [({"status": k[len("status_"):]}, _count(v)) for k, v in sorted(counters.items())
              if k.startswith("status_")])
    _counter(out, "augnet_caster_drops_total", "NTRIP clients and sources the caster closed, by reason.",
             [({"reason": k[len("drop_"):]}, _count(v)) for k, v in sorted(counters.items())
              if k.startswith("drop_")])
    mounts = sorted((snap.get("mounts") or {}).items())
    _counter(out, "augnet_caster_mount_bytes_out_total", "Bytes sent to clients per mountpoint.",
             [({"mount": name}, _count(m.get("bytes_out", 0))) for name, m in mounts])
    _counter(out, "augnet_caster_mount_bytes_in_total", "Bytes received from the source per mountpoint.",
             [({"mount": name}, _count(m.get("bytes_in", 0))) for name, m in mounts])
    return out
