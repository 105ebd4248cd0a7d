"""Simulated world: truth orbits, clocks, atmosphere and receivers (reference stations and trains).

Scenario files (`scenario.py`, built-ins in `scenarios/`) describe a line, its stations and trains
and the error levels; `World` (`world.py`) turns them into observables and truth; `record.py`
writes RINEX, RTCM and truth files; `live.py` streams to an NTRIP caster.  See README.md.
"""
