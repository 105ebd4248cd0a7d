"""Simulated world: truth orbits, clocks, atmosphere, receivers (reference stations and trains)."""
