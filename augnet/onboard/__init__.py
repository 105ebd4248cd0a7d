"""augnet.onboard: the train's positioning core (docs/architecture.md names each module's subject)."""
