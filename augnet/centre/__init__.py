"""augnet.centre (see ../shared/design/architecture.md)."""
