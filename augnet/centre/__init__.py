"""augnet.centre: the network engine (docs/architecture.md names each module's subject)."""
