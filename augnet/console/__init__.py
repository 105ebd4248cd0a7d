"""augnet.console: the operator console (docs/architecture.md)."""
