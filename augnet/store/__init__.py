"""augnet.store (see ../shared/design/architecture.md)."""
