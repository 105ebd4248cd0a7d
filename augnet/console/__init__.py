"""augnet.console (see ../shared/design/architecture.md)."""
