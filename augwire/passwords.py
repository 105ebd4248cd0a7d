"""Password hashes as scrypt (hashlib.scrypt), the format of the caster's user file and the console's
operators and caster users.

Hash format: `scrypt$<log2 N>$<r>$<p>$<salt b64>$<hash b64>`. Parameters N=2^14, r=8, p=1 are
Percival's (scrypt paper, 2009) interactive-login choice and the example in Python's hashlib docs:
~16 MiB and a few tens of ms per check.
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import os

SCRYPT_LOG2_N = 14
SCRYPT_R = 8
SCRYPT_P = 1
SCRYPT_SALT_BYTES = 16
SCRYPT_HASH_BYTES = 32
# hashlib's default maxmem is 32 MiB; scrypt needs 128 * r * N bytes plus overhead.
SCRYPT_MAXMEM_BYTES = 64 * 1024 * 1024


def hash_password(password: str, *, log2_n: int = SCRYPT_LOG2_N, r: int = SCRYPT_R,
                  p: int = SCRYPT_P, salt: bytes | None = None) -> str:
    """The stored form of `password`: scrypt with a random salt (or `salt`, for a fixed dummy hash)."""
    salt = os.urandom(SCRYPT_SALT_BYTES) if salt is None else salt
    digest = hashlib.scrypt(password.encode("utf-8"), salt=salt, n=1 << log2_n, r=r, p=p,
                            maxmem=SCRYPT_MAXMEM_BYTES, dklen=SCRYPT_HASH_BYTES)
    b64 = base64.b64encode
    return f"scrypt${log2_n}${r}${p}${b64(salt).decode()}${b64(digest).decode()}"


def verify_password(password: str, stored: str) -> bool:
    """True when `password` matches the stored scrypt hash; False for any malformed hash."""
    try:
        scheme, log2_n, r, p, salt, digest = stored.split("$")
        if scheme != "scrypt":
            return False
        want = base64.b64decode(digest, validate=True)
        got = hashlib.scrypt(password.encode("utf-8"), salt=base64.b64decode(salt, validate=True),
                             n=1 << int(log2_n), r=int(r), p=int(p), maxmem=SCRYPT_MAXMEM_BYTES,
                             dklen=len(want))
    except (ValueError, TypeError):
        return False
    return hmac.compare_digest(got, want)
