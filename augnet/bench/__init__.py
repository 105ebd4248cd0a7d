"""Benchmarks: each prints figures and a ratio against a named peer, measured side by side in one run."""
