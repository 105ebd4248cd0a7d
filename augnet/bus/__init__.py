"""augnet.bus (see ../shared/design/architecture.md)."""
