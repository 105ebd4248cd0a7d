"""Operator console tests (augnet.console)."""
