"""Fixtures for the caster tests: a caster on a loopback port in a background thread."""

from __future__ import annotations

import pytest

from ntrip_caster.embedded import CasterThread

from .helpers import make_config


@pytest.fixture
def caster():
    """A running caster with test users (train1/trains, station1/stations) and mountpoints
    OPEN (public), BASE01, BASE02 (trains), NEAR (nearest base)."""
    with CasterThread(make_config()) as ct:
        yield ct
