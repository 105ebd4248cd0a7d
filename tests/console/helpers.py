"""Console test helpers: fixture accounts and reading 422 answers."""

from __future__ import annotations

from augnet.store.models import Role

# Cheap scrypt (N=2^10) for the fixture accounts: same format and verification code, less CPU per test.
FAST_HASH = {"log2_n": 10}
PASSWORDS = {"vera": "viewer-secret", "otto": "operator-secret", "ada": "admin-secret"}
ROLES = {"vera": Role.VIEWER, "otto": Role.OPERATOR, "ada": Role.ADMIN}


def error_fields(resp) -> set[str]:
    """The field names a 422 answer blames (the last element of each error's loc)."""
    assert resp.status_code == 422, resp.text
    return {str(e["loc"][-1]) for e in resp.json()["detail"]}
