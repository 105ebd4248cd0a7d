"""augnet.onboard (see ../shared/design/architecture.md)."""
