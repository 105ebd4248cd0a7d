"""NTRIP 1.0 / 2.0 caster: a sans-IO protocol core and an asyncio server."""
