"""RTCM 3 data fields (DF numbers of RTCM 10403.3 section 3.3, Table 3.3-1) used by augnet's messages.

Each field is declared once: bit width, integer kind and scale factor. Names are the DF numbers as
pyrtcm spells them ("DF025", "DF001_7" for a 7-bit reserved field, "ExtSatInfo" for the MSM extended
satellite information), so our decoded values can be compared with pyrtcm's attribute by attribute.

Value convention (the same as pyrtcm): a field with a scale factor decodes to ``raw * scale``
(a float); a field without one decodes to the raw integer; a character field decodes to a one-
character string. Units are those of the standard (e.g. MSM ranges in milliseconds, angles in
semicircles).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum


class Kind(str, Enum):
    UNSIGNED = "u"
    TWOS = "i"  # two's complement
    SIGN_MAG = "s"  # sign-magnitude: MSB is the sign (used by GLONASS fields)
    CHAR = "c"  # one ISO 8859-1 character per 8 bits


@dataclass(frozen=True, slots=True)
class Field:
    name: str
    width: int  # bits
    kind: Kind
    scale: float | int | None  # value = raw * scale; None means the raw integer is the value
    what: str
    raw_min: int = 0  # smallest raw integer the field holds (set from width and kind)
    raw_max: int = 0  # largest


def _field(name: str, width: int, kind: Kind, scale, what: str) -> Field:
    if kind is Kind.TWOS:
        lo, hi = -(1 << (width - 1)), (1 << (width - 1)) - 1
    elif kind is Kind.SIGN_MAG:
        lo, hi = -((1 << (width - 1)) - 1), (1 << (width - 1)) - 1
    else:
        lo, hi = 0, (1 << width) - 1
    return Field(name, width, kind, scale, what, lo, hi)


U, I, S, C = Kind.UNSIGNED, Kind.TWOS, Kind.SIGN_MAG, Kind.CHAR

# Powers of two used as scale factors; exact in binary floating point.
P2 = {n: 2.0**n for n in range(-66, 17)}

_DECLARED: tuple[tuple[str, int, Kind, float | int | None, str], ...] = (
    # --- common
    ("DF001_1", 1, U, None, "reserved, 1 bit"),
    ("DF001_2", 2, U, None, "reserved, 2 bits"),
    ("DF001_7", 7, U, None, "reserved, 7 bits"),
    ("DF002", 12, U, None, "message number"),
    ("DF003", 12, U, None, "reference station id"),
    # --- 1005 / 1006 station coordinates
    ("DF021", 6, U, None, "ITRF realisation year"),
    ("DF022", 1, U, None, "GPS indicator"),
    ("DF023", 1, U, None, "GLONASS indicator"),
    ("DF024", 1, U, None, "Galileo indicator"),
    ("DF141", 1, U, None, "reference-station indicator (0 real, 1 non-physical e.g. VRS)"),
    ("DF025", 38, I, 0.0001, "antenna reference point ECEF X [m]"),
    ("DF142", 1, U, None, "single receiver oscillator indicator"),
    ("DF026", 38, I, 0.0001, "antenna reference point ECEF Y [m]"),
    ("DF364", 2, U, None, "quarter cycle indicator"),
    ("DF027", 38, I, 0.0001, "antenna reference point ECEF Z [m]"),
    ("DF028", 16, U, 0.0001, "antenna height [m]"),
    # --- 1033 descriptors (counters then characters)
    ("DF029", 8, U, None, "antenna descriptor counter"),
    ("DF030", 8, C, None, "antenna descriptor character"),
    ("DF031", 8, U, None, "antenna setup id"),
    ("DF032", 8, U, None, "antenna serial number counter"),
    ("DF033", 8, C, None, "antenna serial number character"),
    ("DF227", 8, U, None, "receiver type descriptor counter"),
    ("DF228", 8, C, None, "receiver type descriptor character"),
    ("DF229", 8, U, None, "receiver firmware version counter"),
    ("DF230", 8, C, None, "receiver firmware version character"),
    ("DF231", 8, U, None, "receiver serial number counter"),
    ("DF232", 8, C, None, "receiver serial number character"),
    # --- 1019 GPS LNAV ephemeris (IS-GPS-200 scale factors; angles in semicircles)
    ("DF009", 6, U, None, "GPS satellite id"),
    ("DF076", 10, U, None, "GPS week number (mod 1024)"),
    ("DF077", 4, U, None, "GPS SV accuracy (URA index)"),
    ("DF078", 2, U, None, "GPS code on L2"),
    ("DF079", 14, I, P2[-43], "GPS IDOT [semicircles/s]"),
    ("DF071", 8, U, None, "GPS IODE"),
    ("DF081", 16, U, 16, "GPS toc [s]"),
    ("DF082", 8, I, P2[-55], "GPS af2 [s/s^2]"),
    ("DF083", 16, I, P2[-43], "GPS af1 [s/s]"),
    ("DF084", 22, I, P2[-31], "GPS af0 [s]"),
    ("DF085", 10, U, None, "GPS IODC"),
    ("DF086", 16, I, P2[-5], "GPS Crs [m]"),
    ("DF087", 16, I, P2[-43], "GPS delta n [semicircles/s]"),
    ("DF088", 32, I, P2[-31], "GPS M0 [semicircles]"),
    ("DF089", 16, I, P2[-29], "GPS Cuc [rad]"),
    ("DF090", 32, U, P2[-33], "GPS eccentricity"),
    ("DF091", 16, I, P2[-29], "GPS Cus [rad]"),
    ("DF092", 32, U, P2[-19], "GPS sqrt(A) [m^0.5]"),
    ("DF093", 16, U, 16, "GPS toe [s]"),
    ("DF094", 16, I, P2[-29], "GPS Cic [rad]"),
    ("DF095", 32, I, P2[-31], "GPS Omega0 [semicircles]"),
    ("DF096", 16, I, P2[-29], "GPS Cis [rad]"),
    ("DF097", 32, I, P2[-31], "GPS i0 [semicircles]"),
    ("DF098", 16, I, P2[-5], "GPS Crc [m]"),
    ("DF099", 32, I, P2[-31], "GPS omega [semicircles]"),
    ("DF100", 24, I, P2[-43], "GPS OMEGADOT [semicircles/s]"),
    ("DF101", 8, I, P2[-31], "GPS tGD [s]"),
    ("DF102", 6, U, None, "GPS SV health"),
    ("DF103", 1, U, None, "GPS L2 P data flag"),
    ("DF137", 1, U, None, "GPS fit interval"),
    # --- 1042 BDS D1/D2 ephemeris (BDS-SIS-ICD scale factors)
    ("DF488", 6, U, None, "BDS satellite id"),
    ("DF489", 13, U, None, "BDS week number"),
    ("DF490", 4, U, None, "BDS URAI"),
    ("DF491", 14, I, P2[-43], "BDS IDOT [semicircles/s]"),
    ("DF492", 5, U, None, "BDS AODE"),
    ("DF493", 17, U, 8, "BDS toc [s]"),
    ("DF494", 11, I, P2[-66], "BDS a2 [s/s^2]"),
    ("DF495", 22, I, P2[-50], "BDS a1 [s/s]"),
    ("DF496", 24, I, P2[-33], "BDS a0 [s]"),
    ("DF497", 5, U, None, "BDS AODC"),
    ("DF498", 18, I, P2[-6], "BDS Crs [m]"),
    ("DF499", 16, I, P2[-43], "BDS delta n [semicircles/s]"),
    ("DF500", 32, I, P2[-31], "BDS M0 [semicircles]"),
    ("DF501", 18, I, P2[-31], "BDS Cuc [rad]"),
    ("DF502", 32, U, P2[-33], "BDS eccentricity"),
    ("DF503", 18, I, P2[-31], "BDS Cus [rad]"),
    ("DF504", 32, U, P2[-19], "BDS sqrt(A) [m^0.5]"),
    ("DF505", 17, U, 8, "BDS toe [s]"),
    ("DF506", 18, I, P2[-31], "BDS Cic [rad]"),
    ("DF507", 32, I, P2[-31], "BDS Omega0 [semicircles]"),
    ("DF508", 18, I, P2[-31], "BDS Cis [rad]"),
    ("DF509", 32, I, P2[-31], "BDS i0 [semicircles]"),
    ("DF510", 18, I, P2[-6], "BDS Crc [m]"),
    ("DF511", 32, I, P2[-31], "BDS omega [semicircles]"),
    ("DF512", 24, I, P2[-43], "BDS OMEGADOT [semicircles/s]"),
    ("DF513", 10, I, 0.1, "BDS TGD1 [ns]"),
    ("DF514", 10, I, 0.1, "BDS TGD2 [ns]"),
    ("DF515", 1, U, None, "BDS SV health (autonomous satellite health flag)"),
    # --- 1045 / 1046 Galileo F/NAV and I/NAV ephemeris (Galileo OS SIS ICD scale factors)
    ("DF252", 6, U, None, "Galileo satellite id"),
    ("DF289", 12, U, None, "Galileo week number"),
    ("DF290", 10, U, None, "Galileo IODnav"),
    ("DF291", 8, U, None, "Galileo SISA index (E1,E5a)"),
    ("DF286", 8, U, None, "Galileo SISA index (E1,E5b)"),
    ("DF292", 14, I, P2[-43], "Galileo IDOT [semicircles/s]"),
    ("DF293", 14, U, 60, "Galileo toc [s]"),
    ("DF294", 6, I, P2[-59], "Galileo af2 [s/s^2]"),
    ("DF295", 21, I, P2[-46], "Galileo af1 [s/s]"),
    ("DF296", 31, I, P2[-34], "Galileo af0 [s]"),
    ("DF297", 16, I, P2[-5], "Galileo Crs [m]"),
    ("DF298", 16, I, P2[-43], "Galileo delta n [semicircles/s]"),
    ("DF299", 32, I, P2[-31], "Galileo M0 [semicircles]"),
    ("DF300", 16, I, P2[-29], "Galileo Cuc [rad]"),
    ("DF301", 32, U, P2[-33], "Galileo eccentricity"),
    ("DF302", 16, I, P2[-29], "Galileo Cus [rad]"),
    ("DF303", 32, U, P2[-19], "Galileo sqrt(A) [m^0.5]"),
    ("DF304", 14, U, 60, "Galileo toe [s]"),
    ("DF305", 16, I, P2[-29], "Galileo Cic [rad]"),
    ("DF306", 32, I, P2[-31], "Galileo Omega0 [semicircles]"),
    ("DF307", 16, I, P2[-29], "Galileo Cis [rad]"),
    ("DF308", 32, I, P2[-31], "Galileo i0 [semicircles]"),
    ("DF309", 16, I, P2[-5], "Galileo Crc [m]"),
    ("DF310", 32, I, P2[-31], "Galileo omega [semicircles]"),
    ("DF311", 24, I, P2[-43], "Galileo OMEGADOT [semicircles/s]"),
    ("DF312", 10, I, P2[-32], "Galileo BGD E1/E5a [s]"),
    ("DF313", 10, I, P2[-32], "Galileo BGD E5b/E1 [s]"),
    ("DF314", 2, U, None, "Galileo E5a signal health status"),
    ("DF315", 1, U, None, "Galileo E5a data validity status"),
    ("DF316", 2, U, None, "Galileo E5b signal health status"),
    ("DF317", 1, U, None, "Galileo E5b data validity status"),
    ("DF287", 2, U, None, "Galileo E1-B signal health status"),
    ("DF288", 1, U, None, "Galileo E1-B data validity status"),
    # --- MSM header (RTCM 10403.3 Table 3.5-78)
    ("DF004", 30, U, None, "GPS epoch time, TOW [ms]"),
    ("DF248", 30, U, None, "Galileo epoch time, TOW [ms]"),
    ("DF427", 30, U, None, "BeiDou epoch time, BDT TOW [ms]"),
    ("DF428", 30, U, None, "QZSS epoch time, TOW [ms]"),
    ("DF546", 30, U, None, "NavIC epoch time, TOW [ms]"),
    ("DF416", 3, U, None, "GLONASS day of week (0 = Sunday, 7 = unknown)"),
    ("DF034", 27, U, None, "GLONASS epoch time tk [ms of day, Moscow time]"),
    ("DF393", 1, U, None, "multiple message bit (1 = more MSM of this system follow for the epoch)"),
    ("DF409", 3, U, None, "issue of data station"),
    ("DF411", 2, U, None, "clock steering indicator"),
    ("DF412", 2, U, None, "external clock indicator"),
    ("DF417", 1, U, None, "divergence-free smoothing indicator"),
    ("DF418", 3, U, None, "smoothing interval"),
    ("DF394", 64, U, None, "satellite mask (MSB = satellite id 1)"),
    ("DF395", 32, U, None, "signal mask (MSB = signal id 1)"),
    ("DF396", 0, U, None, "cell mask, Nsat x Nsig bits (width varies)"),
    # --- MSM satellite data (Table 3.5-79 ff.)
    ("DF397", 8, U, None, "rough range, integer milliseconds (255 = invalid)"),
    ("ExtSatInfo", 4, U, None, "extended satellite information (reserved for GPS/Galileo/BDS/QZSS)"),
    ("DF419", 4, U, None, "GLONASS frequency channel number + 7"),
    ("DF398", 10, U, P2[-10], "rough range modulo 1 ms [ms]"),
    ("DF399", 14, I, None, "rough phase-range rate [m/s] (-8192 = invalid)"),
    # --- MSM signal (cell) data
    ("DF400", 15, I, P2[-24], "fine pseudorange [ms] (-16384 = invalid)"),
    ("DF401", 22, I, P2[-29], "fine phase-range [ms] (-2097152 = invalid)"),
    ("DF402", 4, U, None, "phase-range lock time indicator"),
    ("DF420", 1, U, None, "half-cycle ambiguity indicator"),
    ("DF403", 6, U, None, "CNR [dB-Hz] (0 = not computed)"),
    ("DF404", 15, I, 0.0001, "fine phase-range rate [m/s] (-16384 = invalid)"),
    ("DF405", 20, I, P2[-29], "fine pseudorange, extended resolution [ms] (-524288 = invalid)"),
    ("DF406", 24, I, P2[-31], "fine phase-range, extended resolution [ms] (-8388608 = invalid)"),
    ("DF407", 10, U, None, "phase-range lock time indicator, extended range and resolution"),
    ("DF408", 10, U, P2[-4], "CNR, extended resolution [dB-Hz] (0 = not computed)"),
)

FIELDS: dict[str, Field] = {name: _field(name, w, k, s, what) for name, w, k, s, what in _DECLARED}


def decode_raw(field: Field, raw: int) -> int:
    """Unsigned bits -> signed integer according to the field's kind."""
    if field.kind is Kind.TWOS and raw >> (field.width - 1):
        return raw - (1 << field.width)
    if field.kind is Kind.SIGN_MAG and raw >> (field.width - 1):
        return -(raw & ((1 << (field.width - 1)) - 1))
    return raw


def encode_raw(field: Field, value: int) -> int:
    """Signed integer -> unsigned bits; raises ValueError when out of the field's range."""
    if not field.raw_min <= value <= field.raw_max:
        raise ValueError(
            f"{field.name} ({field.what}): raw value {value} outside [{field.raw_min}, {field.raw_max}]"
        )
    if value < 0:
        if field.kind is Kind.SIGN_MAG:
            return (1 << (field.width - 1)) | -value
        return value + (1 << field.width)
    return value


def to_value(field: Field, raw_signed: int):
    """Signed raw integer -> the value pyrtcm reports (scaled float, int, or character)."""
    if field.kind is Kind.CHAR:
        return chr(raw_signed)
    if field.scale is None:
        return raw_signed
    return raw_signed * field.scale


def from_value(field: Field, value) -> int:
    """A reported value -> the signed raw integer (rounding scaled values to the nearest step)."""
    if field.kind is Kind.CHAR:
        if isinstance(value, str):
            if len(value) != 1:
                raise ValueError(f"{field.name}: expected one character, got {value!r}")
            return ord(value)
        return int(value)
    if field.scale is None:
        if isinstance(value, float) and not value.is_integer():
            raise ValueError(f"{field.name}: expected an integer, got {value!r}")
        return int(value)
    return round(value / field.scale)
