"""Message layouts, declared once as data; the encoders and decoders walk these tables.

Non-MSM messages are a sequence of items: a field name (see ``fields.FIELDS``) or a
``Repeat(counter, item)``: ``counter`` (already read) says how many ``item`` fields follow; they are
named ``item_01``, ``item_02``... as pyrtcm names them.

MSM messages (RTCM 10403.3 section 3.5.12) are header, then each satellite field for all satellites,
then each signal (cell) field for all cells. Which DF carries a role (fine pseudorange, lock time...)
depends on the MSM level; which DF carries the epoch and the extended satellite information depends
on the system. Both are tables below.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Repeat:
    counter: str
    item: str


# RTCM 10403.3 Tables 3.5-4/-5 (1005/1006), 3.5-9 (1033), 3.5-21 (1019), 3.5-109 (1042),
# 3.5-110 (1045, F/NAV), 3.5-111 (1046, I/NAV).
_ARP = ("DF002", "DF003", "DF021", "DF022", "DF023", "DF024", "DF141", "DF025", "DF142", "DF001_1",
        "DF026", "DF364", "DF027")

_GAL_ORBIT = ("DF292", "DF293", "DF294", "DF295", "DF296", "DF297", "DF298", "DF299", "DF300", "DF301",
              "DF302", "DF303", "DF304", "DF305", "DF306", "DF307", "DF308", "DF309", "DF310", "DF311",
              "DF312")

LAYOUTS: dict[int, tuple[str | Repeat, ...]] = {
    1005: _ARP,
    1006: _ARP + ("DF028",),
    1033: ("DF002", "DF003", "DF029", Repeat("DF029", "DF030"), "DF031", "DF032", Repeat("DF032", "DF033"),
           "DF227", Repeat("DF227", "DF228"), "DF229", Repeat("DF229", "DF230"), "DF231",
           Repeat("DF231", "DF232")),
    1019: ("DF002", "DF009", "DF076", "DF077", "DF078", "DF079", "DF071", "DF081", "DF082", "DF083", "DF084",
           "DF085", "DF086", "DF087", "DF088", "DF089", "DF090", "DF091", "DF092", "DF093", "DF094", "DF095",
           "DF096", "DF097", "DF098", "DF099", "DF100", "DF101", "DF102", "DF103", "DF137"),
    1042: ("DF002", "DF488", "DF489", "DF490", "DF491", "DF492", "DF493", "DF494", "DF495", "DF496", "DF497",
           "DF498", "DF499", "DF500", "DF501", "DF502", "DF503", "DF504", "DF505", "DF506", "DF507", "DF508",
           "DF509", "DF510", "DF511", "DF512", "DF513", "DF514", "DF515"),
    # F/NAV: one BGD, E5a health/validity, 7 reserved bits (496 bits = 62 bytes)
    1045: ("DF002", "DF252", "DF289", "DF290", "DF291") + _GAL_ORBIT + ("DF314", "DF315", "DF001_7"),
    # I/NAV: SISA(E1,E5b) in place of SISA(E1,E5a), two BGDs, E5b and E1-B health, 2 reserved bits
    1046: ("DF002", "DF252", "DF289", "DF290", "DF286") + _GAL_ORBIT
          + ("DF313", "DF316", "DF317", "DF287", "DF288", "DF001_2"),
}

# ----------------------------------------------------------------------------------------------
# MSM (RTCM 10403.3 Tables 3.5-78 header, 3.5-80 .. 3.5-87 satellite and signal data)

# Message number = base + level (1..7); the system letter is the RINEX one.
MSM_BASE = {"G": 1070, "R": 1080, "E": 1090, "S": 1100, "J": 1110, "C": 1120, "I": 1130}
MSM_SYSTEM_OF_BASE = {base: sys for sys, base in MSM_BASE.items()}
MSM_LEVELS = (4, 5, 6, 7)  # the levels augnet encodes and decodes (full observables)

# The 30-bit epoch field differs per system: GPS/Galileo/QZSS/BDS/NavIC carry a time of week in
# milliseconds of their own time scale (BDS: BDT = GPST - 14 s); GLONASS carries a 3-bit day of week
# and a 27-bit time of day (Moscow time, UTC+3 h).
MSM_EPOCH_FIELDS = {
    "G": ("DF004",), "R": ("DF416", "DF034"), "E": ("DF248",), "S": ("DF004",), "J": ("DF428",),
    "C": ("DF427",), "I": ("DF546",),
}
# Extended satellite info (MSM5/7): GLONASS frequency channel + 7 (DF419); reserved elsewhere.
MSM_EXT_FIELD = {sys: ("DF419" if sys == "R" else "ExtSatInfo") for sys in MSM_BASE}

MSM_HEADER_TAIL = ("DF393", "DF409", "DF001_7", "DF411", "DF412", "DF417", "DF418", "DF394", "DF395", "DF396")

# Satellite data: role -> DF per level, in transmission order. "ext" is the extended info field.
MSM_SAT_ROLES: dict[int, tuple[tuple[str, str], ...]] = {
    4: (("rough_ms", "DF397"), ("rough_mod", "DF398")),
    5: (("rough_ms", "DF397"), ("ext_info", "ext"), ("rough_mod", "DF398"), ("rough_rate", "DF399")),
    6: (("rough_ms", "DF397"), ("rough_mod", "DF398")),
    7: (("rough_ms", "DF397"), ("ext_info", "ext"), ("rough_mod", "DF398"), ("rough_rate", "DF399")),
}
# Signal (cell) data: role -> DF per level, in transmission order.
MSM_CELL_ROLES: dict[int, tuple[tuple[str, str], ...]] = {
    4: (("fine_pr", "DF400"), ("fine_ph", "DF401"), ("lock", "DF402"), ("half_cycle", "DF420"),
        ("cnr", "DF403")),
    5: (("fine_pr", "DF400"), ("fine_ph", "DF401"), ("lock", "DF402"), ("half_cycle", "DF420"),
        ("cnr", "DF403"), ("fine_rate", "DF404")),
    6: (("fine_pr", "DF405"), ("fine_ph", "DF406"), ("lock", "DF407"), ("half_cycle", "DF420"),
        ("cnr", "DF408")),
    7: (("fine_pr", "DF405"), ("fine_ph", "DF406"), ("lock", "DF407"), ("half_cycle", "DF420"),
        ("cnr", "DF408"), ("fine_rate", "DF404")),
}
SAT_ROLE_NAMES = ("rough_ms", "ext_info", "rough_mod", "rough_rate")
CELL_ROLE_NAMES = ("fine_pr", "fine_ph", "lock", "half_cycle", "cnr", "fine_rate")

# RTCM 10403.3 section 3.5.12.3: the cell mask has at most 64 bits (Nsat x Nsig <= 64); RTKLIB
# rejects larger messages. Observations that need more cells go into several MSM with DF393 = 1.
MSM_MAX_CELLS = 64


def msm_kind(msg_type: int) -> tuple[str, int] | None:
    """(system letter, level) for a supported MSM message number, else None."""
    sys = MSM_SYSTEM_OF_BASE.get(msg_type - msg_type % 10)
    level = msg_type % 10
    if sys is None or level not in MSM_LEVELS:
        return None
    return sys, level


def msm_type(system: str, level: int) -> int:
    if system not in MSM_BASE or level not in MSM_LEVELS:
        raise ValueError(f"no MSM{level} for system {system!r} (levels {MSM_LEVELS}, systems {tuple(MSM_BASE)})")
    return MSM_BASE[system] + level


def sat_fields(system: str, level: int) -> tuple[tuple[str, str], ...]:
    """(role, DF name) of the satellite data, with the system's extended-info field filled in."""
    ext = MSM_EXT_FIELD[system]
    return tuple((role, ext if df == "ext" else df) for role, df in MSM_SAT_ROLES[level])


def cell_fields(level: int) -> tuple[tuple[str, str], ...]:
    return MSM_CELL_ROLES[level]


SUPPORTED_TYPES: tuple[int, ...] = tuple(sorted(LAYOUTS)) + tuple(
    base + lv for base in sorted(MSM_BASE.values()) for lv in MSM_LEVELS
)
