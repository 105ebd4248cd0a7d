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
    """The whole-system runs first: they are the longest in wall-clock time but mostly wait on the real clock,
    so under `make test`'s two workers (one file per worker) they overlap the CPU-bound simulations."""
    items.sort(key=lambda item: item.get_closest_marker("system") is None)
