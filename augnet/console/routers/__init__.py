"""One router per resource; app.py mounts them all under /api (the page and /metrics at the root)."""
