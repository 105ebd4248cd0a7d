"""Shared fixtures: where the real recordings live, and skips with a reason when tools are absent."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from augnet.blas_threads import limit_blas_threads

# The suite runs the numerics as `augnet` does, with one BLAS thread: set before any test module imports numpy.
limit_blas_threads()

REPO_ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO_ROOT.parent / "shared" / "data"
# Hang guard for the long simulations (the network hour, the interpolation figures, the demo scenario):
# pytest-timeout's 600 s (pyproject) cut them off at a load average of 6-11 on two cores (2026-12-01).
LONG_RUN_TIMEOUT_S = 1800


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """../shared/data (real recordings by others); skip when absent, never copied into the repo."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real recordings not available: {SHARED_DATA} is absent")
    return SHARED_DATA


def require_tool(name: str) -> str:
    path = shutil.which(name)
    if path is None:
        pytest.skip(f"{name} not installed (make test installs RTKLIB and curl with apt-get)")
    return path


def pytest_collection_modifyitems(config, items):
    """Longest files first, so that under `make test`'s two workers (one file per worker, handed out in this
    order: the Makefile turns off xdist's reordering by test count, which put the one-test hour-long files last)
    the short files fill in at the end instead of one worker finishing a long file alone: the whole-system runs
    first (the longest in wall-clock time but mostly waiting on the real clock, they overlap the CPU-bound
    simulations), then the files of the long simulations (their LONG_RUN_TIMEOUT_S), every other file with a
    `slow` test, then the rest, each group in collection order."""
    rank: dict[str, int] = {}
    for item in items:
        key = item.nodeid.split("::", 1)[0]
        timeout = item.get_closest_marker("timeout")
        long_run = timeout is not None and bool(timeout.args) and timeout.args[0] >= LONG_RUN_TIMEOUT_S
        r = (0 if item.get_closest_marker("system") else 1 if long_run else
             2 if item.get_closest_marker("slow") else 3)
        rank[key] = min(rank.get(key, 3), r)
    items.sort(key=lambda item: rank[item.nodeid.split("::", 1)[0]])
