"""The one error type of the RINEX readers, and the line-oriented file opening they share."""

from __future__ import annotations

import gzip
import math
import io
import os
from pathlib import Path

# RINEX 3.04 section 5: header labels occupy columns 61-80.
LABEL_COLUMN = 60


class RinexError(ValueError):
    """A malformed RINEX file: carries the file name and the 1-based line number."""

    def __init__(self, path: str | os.PathLike | None, line_no: int | None, message: str):
        self.path = str(path) if path is not None else "<stream>"
        self.line_no = line_no
        self.message = message
        where = f"{self.path}:{line_no}" if line_no is not None else self.path
        super().__init__(f"{where}: {message}")


def read_lines(path: str | os.PathLike) -> list[str]:
    """All lines of a RINEX file (plain or gzip), without line ends.

    Decoded as latin-1 so that no byte can fail to decode (comments from some receivers carry
    non-ASCII bytes); the format itself is ASCII.
    """
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise RinexError(p, None, f"cannot read: {exc.strerror or exc}") from None
    if raw[:2] == b"\x1f\x8b":
        try:
            raw = gzip.decompress(raw)
        except (OSError, EOFError, gzip.BadGzipFile) as exc:
            raise RinexError(p, None, f"corrupt gzip data: {exc}") from None
    return raw.decode("latin-1").splitlines()


def open_text_for_write(path: str | os.PathLike) -> io.TextIOBase:
    """A text stream for writing RINEX; gzip-compressed when the name ends in .gz."""
    p = Path(path)
    if p.suffix == ".gz":
        return io.TextIOWrapper(gzip.open(p, "wb"), encoding="ascii", newline="\n")
    return open(p, "w", encoding="ascii", newline="\n")


def parse_float(text: str, path, line_no: int, what: str, blank: float = 0.0) -> float:
    """A RINEX number: Fortran D or E exponent, blank means `blank`."""
    s = text.strip()
    if not s:
        return blank
    try:
        v = float(s.replace("D", "E").replace("d", "e"))
    except ValueError:
        raise RinexError(path, line_no, f"{what}: not a number: {s!r}") from None
    if not math.isfinite(v):  # float() takes 'nan', 'inf' and 1E+999; RINEX has none of them
        raise RinexError(path, line_no, f"{what}: not a finite number: {s!r}")
    return v


def parse_int(text: str, path, line_no: int, what: str, blank: int | None = 0) -> int:
    s = text.strip()
    if not s:
        if blank is None:
            raise RinexError(path, line_no, f"{what}: missing")
        return blank
    body = s[1:] if s[0] in "+-" else s
    if not is_ascii_digits(body):
        raise RinexError(path, line_no, f"{what}: not an integer: {s!r}")
    return int(s)


def is_ascii_digits(text: str) -> bool:
    """True for a non-empty run of 0-9 (str.isdigit also takes superscripts and other scripts)."""
    return bool(text) and all("0" <= ch <= "9" for ch in text)


def parse_sat_id(text: str, path, line_no: int, default_system: str | None = None) -> str:
    """'G05', 'G 5', ' 5' (RINEX 2, with a default system) -> 'G05'."""
    letter, num = text[:1], text[1:3].strip()
    if letter == " " and default_system:
        letter = default_system
    if len(text) < 3 or not letter.isalpha() or not letter.isascii() or not is_ascii_digits(num):
        raise RinexError(path, line_no, f"bad satellite id {text!r}")
    return f"{letter}{int(num):02d}"
