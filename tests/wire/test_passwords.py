"""scrypt password hashes: the stored format is RFC 7914's scrypt, and verification accepts the right
password only."""

from __future__ import annotations

import base64

from augwire.passwords import SCRYPT_HASH_BYTES, hash_password, verify_password

FAST = {"log2_n": 10}  # cheap N = 2^10: the same code path, for tests


def test_hash_is_rfc7914_scrypt():
    # RFC 7914 section 12: scrypt(P="password", S="NaCl", N=1024, r=8, p=16) starts with these bytes.
    stored = hash_password("password", log2_n=10, r=8, p=16, salt=b"NaCl")
    scheme, log2_n, r, p, salt, digest = stored.split("$")
    assert (scheme, log2_n, r, p, base64.b64decode(salt)) == ("scrypt", "10", "8", "16", b"NaCl")
    want = bytes.fromhex("fdbabe1c9d3472007856e7190d01e9fe7c6ad7cbc8237830e77376634b373162")
    assert base64.b64decode(digest) == want and len(want) == SCRYPT_HASH_BYTES
    assert verify_password("password", stored)


def test_verify_and_reject():
    stored = hash_password("s3cret", **FAST)
    assert verify_password("s3cret", stored)
    assert not verify_password("s3cre", stored) and not verify_password("s3cret ", stored)
    assert hash_password("s3cret", **FAST) != stored  # a fresh salt each time
    assert verify_password("pässwörd", hash_password("pässwörd", **FAST))


def test_malformed_hashes_are_rejected_not_raised():
    good = hash_password("x", **FAST)
    for bad in ("", "scrypt$bad", "md5$1$2$3$4$5", good.replace("scrypt$", "bcrypt$"),
                good.rsplit("$", 1)[0] + "$not base64!", "scrypt$x$8$1$AAAA$AAAA", "scrypt$10$8$1$!!$AAAA"):
        assert not verify_password("x", bad)
