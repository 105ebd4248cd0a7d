"""Console response time: p50 / p99 of the main GET routes against a running console.

Requests are sequential over one keep-alive connection (what a page or a scraper does), after a warm-up, so
the figures are the server's response time plus loopback, not client queueing.
"""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass

import httpx

# The routes a page and a monitoring system hit all the time (the "main GET routes").
MAIN_GET_ROUTES = (
    "/api/stations",
    "/api/network",
    "/api/trains",
    "/api/alarms",
    "/api/caster",
    "/api/caster/mountpoints",
    "/api/caster/clients",
    "/api/quality?limit=100",
    "/api/audit?limit=50",
    "/api/live/snapshot",
    "/metrics",
)
P99_GOAL_MS = 50.0  # issue 8: console p99 for the main GET routes while `augnet up demo` runs
WARMUP_REQUESTS = 5
REQUEST_TIMEOUT_S = 10.0


def percentile(values: list[float], pct: float) -> float:
    """Nearest-rank percentile (no interpolation: the p99 of 200 samples is the 198th smallest)."""
    if not values:
        raise ValueError("no samples")
    ordered = sorted(values)
    rank = max(1, int(-(-pct * len(ordered) // 100)))  # ceil(pct/100 * n)
    return ordered[min(rank, len(ordered)) - 1]


@dataclass(frozen=True)
class RouteTiming:
    route: str
    n: int
    p50_ms: float
    p99_ms: float
    max_ms: float
    mean_ms: float
    errors: int


def measure(url: str, token: str, requests_per_route: int = 200,
            routes: tuple[str, ...] = MAIN_GET_ROUTES) -> list[RouteTiming]:
    """Time every route; a non-200 answer counts as an error (and its time is still a sample)."""
    out = []
    headers = {"Authorization": f"Bearer {token}"}
    with httpx.Client(base_url=url.rstrip("/"), headers=headers, timeout=REQUEST_TIMEOUT_S) as client:
        for route in routes:
            for _ in range(WARMUP_REQUESTS):
                client.get(route)
            samples, errors = [], 0
            for _ in range(requests_per_route):
                t0 = time.perf_counter()
                r = client.get(route)
                r.read()
                samples.append((time.perf_counter() - t0) * 1000.0)
                errors += r.status_code != 200
            out.append(RouteTiming(route, len(samples), percentile(samples, 50), percentile(samples, 99),
                                   max(samples), statistics.fmean(samples), errors))
    return out


def overall(timings: list[RouteTiming]) -> tuple[float, float]:
    """(worst p50, worst p99) over the routes [ms]."""
    return max(t.p50_ms for t in timings), max(t.p99_ms for t in timings)
