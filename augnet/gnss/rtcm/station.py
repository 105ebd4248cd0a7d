"""Station messages every reference stream carries: 1005/1006 (antenna reference point), 1033 (descriptors),
and the MSM epoch-time field."""

from __future__ import annotations

from augnet.gnss import time as gtime
from augnet.gnss.rtcm.codec import RtcmMessage, text_fields

MS_PER_WEEK = 7 * 86_400_000


def arp_message(station_id: int, ecef_m, antenna_height_m: float | None = None,
                non_physical: bool = False) -> RtcmMessage:
    """1005 (or 1006 with an antenna height): stationary antenna reference point, GPS + Galileo flagged
    (BDS is signalled by its MSM). A VRS sets DF022-DF024 the same way and DF141 = 1 (non-physical, a
    computed reference station, RTCM 10403.3 DF141), which rovers read to model its residual atmosphere."""
    x, y, z = (float(v) for v in ecef_m)
    fields = dict(DF003=station_id, DF021=0, DF022=1, DF023=0, DF024=1, DF141=int(bool(non_physical)), DF025=x, DF142=1,
                  DF001_1=0, DF026=y, DF364=0, DF027=z)
    if antenna_height_m is None:
        return RtcmMessage(1005, dict(DF002=1005, **fields))
    return RtcmMessage(1006, dict(DF002=1006, **fields, DF028=float(antenna_height_m)))


def descriptor_message(station_id: int, serial: str, antenna: str, receiver: str, firmware: str) -> RtcmMessage:
    """1033: antenna and receiver descriptors (what RINEX headers and casters show)."""
    f: dict[str, object] = dict(DF002=1033, DF003=station_id, DF031=0)
    f.update(text_fields("DF030", "DF029", antenna))
    f.update(text_fields("DF033", "DF032", serial))
    f.update(text_fields("DF228", "DF227", receiver))
    f.update(text_fields("DF230", "DF229", firmware))
    f.update(text_fields("DF232", "DF231", serial))
    return RtcmMessage(1033, f)


def msm_epoch_ms(system: str, t_gpst: float) -> int:
    """The MSM epoch field: time of week [ms] in the system's own time (BDT for BeiDou)."""
    _, tow = gtime.system_week_tow(system, t_gpst)
    return int(round(float(tow) * 1000.0)) % MS_PER_WEEK
