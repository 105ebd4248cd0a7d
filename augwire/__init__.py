"""augwire: the wire primitives the caster and augnet both speak, on the standard library and numpy only.

  crc24q.py        CRC-24Q (RTCM 10403.3 section 4.2): table-driven byte loop, one-gather numpy form, rows
  rtcm_framing.py  RTCM 3 frames: build, find, split; the sans-IO framer that counts and skips bad input;
                   the caster's forwarding aligner
  chunked.py       HTTP/1.1 chunked transfer coding (RFC 9112 section 7.1): encoder, sans-IO decoder
  passwords.py     scrypt password hashes (the caster's user file and the console's operators)
  errors.py        NtripProtocolError, the one error the NTRIP wire cores raise (carries the HTTP status)
  throttle.py      failed-login throttling per key (exponential lock), shared by the console and the caster

Rule: nothing here imports `augnet`, `ntrip_caster` or any third-party package but numpy, so the caster
can use it and still import nothing from `augnet` (tests/wire/test_imports.py checks both). The package
imports no submodule itself: a user of `passwords` does not pay for numpy.
"""
