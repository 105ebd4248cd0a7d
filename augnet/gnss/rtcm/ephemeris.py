"""Broadcast ephemerides <-> RTCM 1019 (GPS), 1042 (BeiDou), 1045/1046 (Galileo F/NAV, I/NAV).

One table per message maps each `Ephemeris` attribute to its data field and unit conversion
(RINEX keeps radians, RTCM and the ICDs semicircles). The same table quantises a simulated
ephemeris to the broadcast resolution, so what the simulator writes to nav.rnx is exactly what a
receiver decodes from the RTCM stream, and turns a decoded message back into an `Ephemeris`
(`message_ephemeris`), with its truncated week resolved against a reference time.
"""

from __future__ import annotations

import math

from augnet.gnss.ephemeris import Ephemeris
from augnet.gnss.rtcm.codec import RtcmMessage
from augnet.gnss.rtcm.fields import FIELDS, from_value, to_value

SEMICIRCLE_RAD = 3.1415926535898  # IS-GPS-200 / BDS / Galileo ICDs' value of pi for semicircles

# (attribute, data field, factor: field value = attribute * factor)
_ORBIT_GPS = (
    ("idot", "DF079", 1 / SEMICIRCLE_RAD), ("toc", "DF081", 1.0), ("af2", "DF082", 1.0),
    ("af1", "DF083", 1.0), ("af0", "DF084", 1.0), ("crs", "DF086", 1.0),
    ("delta_n", "DF087", 1 / SEMICIRCLE_RAD), ("m0", "DF088", 1 / SEMICIRCLE_RAD), ("cuc", "DF089", 1.0),
    ("e", "DF090", 1.0), ("cus", "DF091", 1.0), ("sqrt_a", "DF092", 1.0), ("toe", "DF093", 1.0),
    ("cic", "DF094", 1.0), ("omega0", "DF095", 1 / SEMICIRCLE_RAD), ("cis", "DF096", 1.0),
    ("i0", "DF097", 1 / SEMICIRCLE_RAD), ("crc", "DF098", 1.0), ("omega", "DF099", 1 / SEMICIRCLE_RAD),
    ("omega_dot", "DF100", 1 / SEMICIRCLE_RAD), ("tgd", "DF101", 1.0),
)
_ORBIT_BDS = (
    ("idot", "DF491", 1 / SEMICIRCLE_RAD), ("toc", "DF493", 1.0), ("af2", "DF494", 1.0),
    ("af1", "DF495", 1.0), ("af0", "DF496", 1.0), ("crs", "DF498", 1.0),
    ("delta_n", "DF499", 1 / SEMICIRCLE_RAD), ("m0", "DF500", 1 / SEMICIRCLE_RAD), ("cuc", "DF501", 1.0),
    ("e", "DF502", 1.0), ("cus", "DF503", 1.0), ("sqrt_a", "DF504", 1.0), ("toe", "DF505", 1.0),
    ("cic", "DF506", 1.0), ("omega0", "DF507", 1 / SEMICIRCLE_RAD), ("cis", "DF508", 1.0),
    ("i0", "DF509", 1 / SEMICIRCLE_RAD), ("crc", "DF510", 1.0), ("omega", "DF511", 1 / SEMICIRCLE_RAD),
    ("omega_dot", "DF512", 1 / SEMICIRCLE_RAD), ("tgd1", "DF513", 1e9), ("tgd2", "DF514", 1e9),
)
_ORBIT_GAL = (
    ("idot", "DF292", 1 / SEMICIRCLE_RAD), ("toc", "DF293", 1.0), ("af2", "DF294", 1.0),
    ("af1", "DF295", 1.0), ("af0", "DF296", 1.0), ("crs", "DF297", 1.0),
    ("delta_n", "DF298", 1 / SEMICIRCLE_RAD), ("m0", "DF299", 1 / SEMICIRCLE_RAD), ("cuc", "DF300", 1.0),
    ("e", "DF301", 1.0), ("cus", "DF302", 1.0), ("sqrt_a", "DF303", 1.0), ("toe", "DF304", 1.0),
    ("cic", "DF305", 1.0), ("omega0", "DF306", 1 / SEMICIRCLE_RAD), ("cis", "DF307", 1.0),
    ("i0", "DF308", 1 / SEMICIRCLE_RAD), ("crc", "DF309", 1.0), ("omega", "DF310", 1 / SEMICIRCLE_RAD),
    ("omega_dot", "DF311", 1 / SEMICIRCLE_RAD), ("bgd_e5a_e1", "DF312", 1.0), ("bgd_e5b_e1", "DF313", 1.0),
)
ORBIT_FIELDS = {"G": _ORBIT_GPS, "C": _ORBIT_BDS, "E": _ORBIT_GAL}
MESSAGE_TYPE = {"G": 1019, "C": 1042, "E": 1046}
GPS_WEEK_ROLLOVER = 1024  # DF076 holds the GPS week modulo 1024


def _ura_index(accuracy_m: float) -> int:
    """GPS URA / BDS URAI index (IS-GPS-200 20.3.3.3.1.3): smallest index whose bound covers it."""
    bounds = (2.4, 3.4, 4.85, 6.85, 9.65, 13.65, 24.0, 48.0, 96.0, 192.0, 384.0, 768.0, 1536.0, 3072.0, 6144.0)
    for i, b in enumerate(bounds):
        if accuracy_m <= b:
            return i
    return 15


def _sisa_index(accuracy_m: float) -> int:
    """Galileo SISA index (OS SIS ICD 5.1.11)."""
    x = accuracy_m
    if x < 0.5:
        return int(round(x / 0.01))
    if x < 1.0:
        return 50 + int(round((x - 0.5) / 0.02))
    if x < 2.0:
        return 75 + int(round((x - 1.0) / 0.04))
    if x < 6.0:
        return 100 + int(round((x - 2.0) / 0.16))
    return 255


# Angles that may take any value: wrapped into the signed semicircle range [-1, 1) the fields hold.
WRAPPED_ANGLES = frozenset({"m0", "omega0", "omega"})


def _field_value(attr: str, df: str, value: float) -> float:
    """The field value of an attribute: scaled, angles wrapped so that +1 semicircle becomes -1."""
    if attr not in WRAPPED_ANGLES:
        return value
    f = FIELDS[df]
    raw = round(value / f.scale)
    half = 1 << (f.width - 1)
    raw = (raw + half) % (2 * half) - half  # +2^31 steps (exactly +pi) wraps to -2^31 (-pi)
    return raw * f.scale


def _quantised(df: str, value: float) -> float:
    f = FIELDS[df]
    return float(to_value(f, from_value(f, value)))


def quantise(eph: Ephemeris) -> Ephemeris:
    """The ephemeris with every orbit and clock parameter on its broadcast resolution."""
    changes = {}
    for attr, df, factor in ORBIT_FIELDS[eph.system]:
        changes[attr] = _quantised(df, _field_value(attr, df, getattr(eph, attr) * factor)) / factor
    return eph.replace(**changes)


def ephemeris_message(eph: Ephemeris) -> RtcmMessage:
    """The RTCM 1019 / 1042 / 1046 message of a broadcast ephemeris."""
    s = eph.system
    fields: dict[str, object] = {}
    for attr, df, factor in ORBIT_FIELDS[s]:
        fields[df] = _field_value(attr, df, getattr(eph, attr) * factor)
    if s == "G":
        fields.update(DF009=eph.prn, DF076=eph.week % 1024, DF077=_ura_index(eph.accuracy_m),
                      DF078=eph.codes_on_l2, DF071=eph.iode, DF085=eph.iodc, DF102=eph.health,
                      DF103=eph.l2p_data_flag, DF137=0 if eph.fit_interval_h <= 4.0 else 1)
    elif s == "C":
        fields.update(DF488=eph.prn, DF489=eph.week, DF490=_ura_index(eph.accuracy_m), DF492=eph.iode,
                      DF497=eph.iodc % 32, DF515=eph.health & 1)
    elif s == "E":
        fields.update(DF252=eph.prn, DF289=eph.week, DF290=eph.iode, DF286=_sisa_index(eph.accuracy_m),
                      DF316=0, DF317=0, DF287=0, DF288=0)
    else:
        raise ValueError(f"no RTCM ephemeris message for system {s!r}")
    return RtcmMessage(MESSAGE_TYPE[s], fields)


def wrap_angle(rad: float) -> float:
    """An angle in [-pi, pi): semicircle fields are signed and hold [-1, 1)."""
    return math.remainder(rad, 2 * math.pi)


# Galileo data-source bits of a decoded message (RINEX 3.04 Table A8): I/NAV E1-B with the E5b/E1 clock,
# F/NAV E5a with the E5a/E1 clock.
GAL_DATA_SOURCES = {1046: 0b10_0000_0101, 1045: 0b01_0000_0010}


def _resolve_week(week_mod: int, modulus: int, t_ref_week: int) -> int:
    """The full week nearest a reference week, given the week modulo `modulus`."""
    base = t_ref_week - (t_ref_week % modulus) + week_mod
    candidates = (base - modulus, base, base + modulus)
    return min(candidates, key=lambda w: abs(w - t_ref_week))


def message_ephemeris(msg: RtcmMessage, t_ref_gpst: float) -> Ephemeris:
    """An `Ephemeris` from a decoded 1019 / 1042 / 1045 / 1046 message.

    `t_ref_gpst` (any time within half a roll-over period, e.g. now or the stream's epoch) resolves the
    truncated week numbers (GPS: 10 bits; Galileo: 12 bits; BDS: 13 bits).
    """
    from augnet.gnss import time as gtime

    f = msg.fields
    t = msg.msg_type
    system = {1019: "G", 1042: "C", 1045: "E", 1046: "E"}.get(t)
    if system is None:
        raise ValueError(f"message {t} is not an ephemeris")
    orbit = ORBIT_FIELDS[system]
    if t == 1045:  # F/NAV: same orbit fields; BGD E5b/E1 absent
        orbit = tuple(item for item in orbit if item[0] != "bgd_e5b_e1")
    values = {attr: float(f[df]) / factor for attr, df, factor in orbit}
    ref_week, _ = gtime.system_week_tow(system, t_ref_gpst)
    ref_week = int(ref_week)
    if system == "G":
        week = _resolve_week(int(f["DF076"]), GPS_WEEK_ROLLOVER, ref_week)
        extra = dict(prn=int(f["DF009"]), iode=int(f["DF071"]), iodc=int(f["DF085"]), health=int(f["DF102"]),
                     codes_on_l2=int(f["DF078"]), l2p_data_flag=int(f["DF103"]),
                     fit_interval_h=4.0 if int(f["DF137"]) == 0 else 6.0)
    elif system == "C":
        week = _resolve_week(int(f["DF489"]), 8192, ref_week)
        extra = dict(prn=int(f["DF488"]), iode=int(f["DF492"]), iodc=int(f["DF497"]), health=int(f["DF515"]))
    else:
        week = _resolve_week(int(f["DF289"]), 4096, ref_week)
        # signal health and data validity bits: any set one makes the set unusable
        health = (int(f.get("DF287", 0)) << 4) | (int(f.get("DF288", 0)) << 3) | (int(f.get("DF314", 0)) << 1) \
            | int(f.get("DF315", 0))
        extra = dict(prn=int(f["DF252"]), iode=int(f["DF290"]), data_sources=GAL_DATA_SOURCES[t], health=health)
    return Ephemeris(system=system, week=week, **values, **extra)
