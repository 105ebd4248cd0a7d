"""ANTEX 1.4 antenna phase-centre models (IGS; Rothacher and Schmid, "ANTEX: The Antenna Exchange Format,
Version 1.4", igs.org antex14.txt): receiver antennas by type and radome, per frequency the phase-centre
offset (PCO, north/east/up from the antenna reference point, ARP) and the phase-centre variations (PCV, by
zenith angle, and by azimuth where calibrated).

`read_antex(path)` (plain or gzip) gives an `AntexFile`; `AntexFile.receiver("TRM41249.00", "NONE")` the
`ReceiverAntenna`, falling back to radome NONE (flagged `radome_fallback`) as the IGS does when a radome has
no calibration of its own (the hint in igs05.atx's header). `ReceiverAntenna.correction_m(...)` is the
phase-centre correction along the line of sight, vectorised over satellites:

    correction = e . PCO - PCV(zenith, azimuth)        [m]

with e the unit vector to the satellite in the local east/north/up frame. It is what an observed range gets
added to be referred to the ARP (equivalently: the range from the phase centre is the ARP's range minus it).
RTKLIB's antmodel() (rtkcmn.c) computes its negative, dant = -e . off + pcv, and adds dant to the modelled
range: the same convention.

Satellite antenna entries are parsed (`AntexFile.satellites`) but not applied: broadcast ephemerides give the
position of the satellite's antenna phase centre already (IS-GPS-200: the broadcast orbit is that of the L1/L2
phase centre), so adding the IGS satellite PCO to them would count it twice.

A malformed file raises `AntexError` naming the file and line.
"""

from __future__ import annotations

import gzip
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

MM_TO_M = 1e-3  # ANTEX gives offsets and variations in millimetres
NO_RADOME = "NONE"  # the radome code of an uncovered antenna (IGS rcvr_ant.tab)
# the antenna type of a VRS or of observations already referred to the ARP (Trimble's name, used by
# commercial networks in RTCM 1007/1008/1033 and RINEX ANT # / TYPE)
NULL_ANTENNA = "ADVNULLANTENNA"
SUPPORTED_VERSION = 1.4
LABEL_COLUMN = 60  # ANTEX header labels start at column 61 (like RINEX)


LABELS = frozenset((
    "ANTEX VERSION / SYST", "PCV TYPE / REFANT", "COMMENT", "END OF HEADER", "START OF ANTENNA",
    "TYPE / SERIAL NO", "METH / BY / # / DATE", "DAZI", "ZEN1 / ZEN2 / DZEN", "# OF FREQUENCIES", "VALID FROM",
    "VALID UNTIL", "SINEX CODE", "START OF FREQUENCY", "NORTH / EAST / UP", "END OF FREQUENCY",
    "START OF FREQ RMS", "END OF FREQ RMS", "END OF ANTENNA"))


def _label(line: str) -> str:
    """The header label of a line, or '' for a data line (PCV rows run past column 60)."""
    text = line[LABEL_COLUMN:].strip()
    return text if text in LABELS else ""


class AntexError(ValueError):
    """A malformed ANTEX file: the message names the file and line."""


@dataclass(frozen=True)
class FrequencyModel:
    """One frequency's model: PCO [m] (north, east, up) and PCV [m] on a zenith (x azimuth) grid."""

    pco_neu_m: np.ndarray  # (3,)
    zenith_deg: np.ndarray  # (Z,)
    noazi_m: np.ndarray  # (Z,) azimuth-independent PCV
    azimuth_deg: np.ndarray | None = None  # (A,) 0..360 when azimuth-dependent
    pcv_m: np.ndarray | None = None  # (A, Z)

    def pcv(self, zenith_deg, azimuth_deg=None) -> np.ndarray:
        """PCV [m] at zenith angles (and azimuths): linear in zenith, bilinear in azimuth when calibrated."""
        z = np.asarray(zenith_deg, float)
        if self.pcv_m is None or azimuth_deg is None:
            return np.interp(z, self.zenith_deg, self.noazi_m)
        a = np.mod(np.asarray(azimuth_deg, float), 360.0)
        bad = ~(np.isfinite(a) & np.isfinite(z))  # a satellite without a position: NaN, not an index
        a, z = np.where(bad, 0.0, a), np.where(bad, 0.0, z)
        az = self.azimuth_deg
        step = az[1] - az[0]
        fa = np.clip(a / step, 0.0, len(az) - 1.0)
        i0 = np.minimum(np.floor(fa).astype(int), len(az) - 2)
        w = fa - i0
        zi = np.clip(z, self.zenith_deg[0], self.zenith_deg[-1])
        fz = (zi - self.zenith_deg[0]) / (self.zenith_deg[1] - self.zenith_deg[0])
        j0 = np.minimum(np.floor(fz).astype(int), len(self.zenith_deg) - 2)
        v = fz - j0
        p = self.pcv_m
        lo = p[i0, j0] * (1 - v) + p[i0, j0 + 1] * v
        hi = p[i0 + 1, j0] * (1 - v) + p[i0 + 1, j0 + 1] * v
        return np.where(bad, np.nan, lo * (1 - w) + hi * w)


@dataclass
class ReceiverAntenna:
    """A receiver antenna's calibration: per ANTEX frequency code ('G01', 'G02', 'E05', ...) its model."""

    antenna_type: str  # 20 characters: type (16) + radome (4), as in ANTEX / RINEX ANT # / TYPE
    frequencies: dict[str, FrequencyModel]
    radome_fallback: bool = False  # the radome asked for was not calibrated: radome NONE's values
    source: str = ""

    @property
    def type_name(self) -> str:
        return self.antenna_type[:16].strip()

    @property
    def radome(self) -> str:
        return self.antenna_type[16:20].strip() or NO_RADOME

    def frequency(self, system: str, band: str) -> tuple[FrequencyModel, bool]:
        """The model of a system's RINEX band ('G', '1' -> 'G01'), and whether it was a stand-in: a missing
        frequency takes GPS's of the same band, else GPS L1 for band 1 and L2 for any other (RTKLIB does the
        same for frequencies without their own calibration)."""
        code = f"{system}{int(band):02d}"
        if code in self.frequencies:
            return self.frequencies[code], False
        for alt in (f"G{int(band):02d}", "G01" if band == "1" else "G02"):
            if alt in self.frequencies:
                return self.frequencies[alt], True
        return next(iter(self.frequencies.values())), True

    def correction_m(self, azimuth_rad, elevation_rad, sats, codes) -> np.ndarray:
        """(S, F) phase-centre correction [m] (e . PCO - PCV) for satellites `sats` ('G05', ...) on the RINEX
        codes `codes` (S, F) ('1C', '2W'; '' -> 0), at azimuth/elevation (S,) [rad]. Added to an observed range,
        it refers the observation to the ARP; NaN angles give NaN."""
        az = np.asarray(azimuth_rad, float)
        el = np.asarray(elevation_rad, float)
        codes = np.asarray(codes)
        if codes.ndim == 1:
            codes = codes[:, None]
        cos_el = np.cos(el)
        e_neu = np.stack([np.cos(az) * cos_el, np.sin(az) * cos_el, np.sin(el)], axis=-1)  # (S, 3)
        zen = 90.0 - np.degrees(el)
        azd = np.degrees(az)
        out = np.zeros(codes.shape)
        systems = np.array([str(s)[0] for s in sats])
        for key in {(sy, str(c)[0]) for sy, row in zip(systems, codes) for c in row if c}:
            system, band = key
            model, _ = self.frequency(system, band)
            rows = systems == system
            cols_mask = np.char.startswith(codes.astype(str), band) & rows[:, None]
            r, c = np.nonzero(cols_mask)
            if not r.size:
                continue
            out[r, c] = e_neu[r] @ model.pco_neu_m - model.pcv(zen[r], azd[r])
        return out

    def stand_ins(self, sats, codes) -> list[str]:
        """The system/band pairs of `codes` this calibration has no frequency of its own for."""
        systems = [str(s)[0] for s in sats]
        missing = set()
        for sy, row in zip(systems, np.atleast_2d(codes)):
            for c in row:
                if c and self.frequency(sy, str(c)[0])[1]:
                    missing.add(f"{sy}{int(str(c)[0]):02d}")
        return sorted(missing)


@dataclass
class AntexFile:
    path: str
    version: float
    pcv_type: str  # 'A' absolute, 'R' relative
    receivers: dict[str, ReceiverAntenna] = field(default_factory=dict)  # 20-character type+radome
    satellites: dict[str, list[dict]] = field(default_factory=dict)  # 'G05' -> entries (valid from/until, freqs)

    def receiver(self, antenna_type: str, radome: str | None = None, warn: bool = True) -> ReceiverAntenna | None:
        """The calibration of `antenna_type` (the RINEX ANT # / TYPE field: type in 16 characters, radome in the
        next 4; or the type alone with `radome`); radome NONE's when the radome has none (flagged), None when
        the type is unknown or the null antenna."""
        name, dome = split_antenna_type(antenna_type, radome)
        if not name or name == NULL_ANTENNA:
            return None
        key = f"{name:<16}{dome:<4}"
        ant = self.receivers.get(key)
        if ant is not None:
            return ant
        base = self.receivers.get(f"{name:<16}{NO_RADOME:<4}")
        if base is None:
            return None
        if warn:
            warnings.warn(f"{self.path}: no calibration of {name} with radome {dome}; using radome {NO_RADOME}'s "
                          "(as the IGS does)", stacklevel=2)
        return ReceiverAntenna(key, base.frequencies, radome_fallback=True, source=base.source)


@dataclass(frozen=True)
class AntennaSetup:
    """A receiver's antenna as set up: its calibration (None: phase centre at the ARP) and the ARP's offset from
    the marker (RINEX ANTENNA: DELTA H/E/N as north, east, up [m]). `correction_m` refers observations to the
    marker: e . (delta + PCO) - PCV, as RTKLIB's antmodel() with the antenna delta (pos2 ant*-antdel)."""

    antenna: ReceiverAntenna | None
    delta_neu_m: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def correction_m(self, azimuth_rad, elevation_rad, sats, codes) -> np.ndarray:
        az = np.asarray(azimuth_rad, float)
        el = np.asarray(elevation_rad, float)
        e_neu = np.stack([np.cos(az) * np.cos(el), np.sin(az) * np.cos(el), np.sin(el)], axis=-1)
        codes = np.asarray(codes)
        codes = codes[:, None] if codes.ndim == 1 else codes
        lever = (e_neu @ np.asarray(self.delta_neu_m, float))[:, None] * (np.char.str_len(codes.astype(str)) > 0)
        if self.antenna is None:
            return lever
        return self.antenna.correction_m(az, el, sats, codes) + lever


def split_antenna_type(antenna_type: str, radome: str | None = None) -> tuple[str, str]:
    """('TRM41249.00', 'NONE') from 'TRM41249.00     NONE' (ANTEX/RINEX columns) or from a space-separated
    type and radome; an empty radome is NONE."""
    text = antenna_type.rstrip()
    if radome is not None:
        return text.strip(), (radome.strip() or NO_RADOME)
    if len(text) > 16 and text[16:20].strip():
        return text[:16].strip(), text[16:20].strip()
    parts = text.split()
    if len(parts) >= 2:
        return parts[0], parts[1]
    return text.strip(), NO_RADOME


def _lines(path: Path) -> list[str]:
    opener = gzip.open if path.name.endswith(".gz") else open
    try:
        with opener(path, "rt", errors="replace") as f:
            return f.read().splitlines()
    except (OSError, EOFError) as exc:
        raise AntexError(f"{path}: cannot read ({exc})") from None


def _floats(text: str, path, ln: int, what: str) -> list[float]:
    try:
        return [float(x) for x in text.split()]
    except ValueError:
        raise AntexError(f"{path}:{ln}: {what}: not numbers: {text.strip()!r}") from None


def read_antex(path: str | os.PathLike) -> AntexFile:
    """Read an ANTEX 1.4 file (plain or .gz): every receiver antenna, and the satellite entries."""
    path = Path(path)
    lines = _lines(path)
    if not lines or "ANTEX VERSION / SYST" not in lines[0]:
        raise AntexError(f"{path}:1: not an ANTEX file (no 'ANTEX VERSION / SYST')")
    version = _floats(lines[0][:8], path, 1, "version")
    if not version or version[0] > SUPPORTED_VERSION + 1e-9:
        raise AntexError(f"{path}:1: ANTEX version {lines[0][:8].strip()!r} (this reader knows up to "
                         f"{SUPPORTED_VERSION})")
    out = AntexFile(str(path), version[0], "A")
    i = 1
    while i < len(lines) and "END OF HEADER" not in lines[i][LABEL_COLUMN:]:
        if "PCV TYPE / REFANT" in lines[i][LABEL_COLUMN:]:
            out.pcv_type = lines[i][0:1]
        i += 1
    if i == len(lines):
        raise AntexError(f"{path}: no END OF HEADER")
    i += 1
    while i < len(lines):
        label = _label(lines[i])
        if label == "START OF ANTENNA":
            i = _antenna(lines, i + 1, path, out)
        elif label == "COMMENT" or not lines[i].strip():
            i += 1
        else:
            raise AntexError(f"{path}:{i + 1}: {lines[i].strip()[:40]!r} outside an antenna block")
    return out


def _antenna(lines: list[str], i: int, path: Path, out: AntexFile) -> int:
    """Parse one antenna block from line index i (after START OF ANTENNA); returns the index after its end."""
    start = i
    ant_type = serial = ""
    dazi = None
    zen = None
    freqs: dict[str, FrequencyModel] = {}
    valid_from = valid_until = None
    while i < len(lines):
        line = lines[i]
        label = _label(line)
        ln = i + 1
        if label == "TYPE / SERIAL NO":
            ant_type, serial = line[0:20], line[20:40].strip()
        elif label == "DAZI":
            dazi = _floats(line[2:8], path, ln, "DAZI")[0]
        elif label == "ZEN1 / ZEN2 / DZEN":
            z = _floats(line[2:20], path, ln, "ZEN1 / ZEN2 / DZEN")
            if len(z) != 3 or z[2] <= 0 or z[1] <= z[0]:
                raise AntexError(f"{path}:{ln}: ZEN1 / ZEN2 / DZEN: {line[:20].strip()!r}")
            zen = np.arange(z[0], z[1] + z[2] / 2, z[2])
        elif label == "VALID FROM":
            valid_from = line[:43].strip()
        elif label == "VALID UNTIL":
            valid_until = line[:43].strip()
        elif label == "START OF FREQUENCY":
            if zen is None or dazi is None:
                raise AntexError(f"{path}:{ln}: START OF FREQUENCY before DAZI and ZEN1 / ZEN2 / DZEN")
            code = line[3:6].strip()
            i, model = _frequency(lines, i + 1, path, code, zen, dazi)
            freqs[code] = model
            continue
        elif label == "END OF ANTENNA":
            if not ant_type.strip():
                raise AntexError(f"{path}:{start}: antenna without TYPE / SERIAL NO")
            if not freqs:
                raise AntexError(f"{path}:{start}: antenna {ant_type.strip()!r} without frequencies")
            key = f"{ant_type[:16].strip():<16}{ant_type[16:20].strip() or NO_RADOME:<4}"
            if _is_satellite(ant_type, serial):
                out.satellites.setdefault(serial[:3], []).append(
                    {"type": ant_type.strip(), "valid_from": valid_from, "valid_until": valid_until,
                     "frequencies": freqs})
            else:
                out.receivers.setdefault(key, ReceiverAntenna(key, freqs, source=f"{path.name}:{start}"))
            return i + 1
        elif label == "START OF ANTENNA":
            raise AntexError(f"{path}:{ln}: START OF ANTENNA inside the antenna block of line {start}")
        i += 1
    raise AntexError(f"{path}:{start}: antenna block without END OF ANTENNA")


def _is_satellite(ant_type: str, serial: str) -> bool:
    """Satellite entries carry the PRN code (e.g. 'G05') in the serial field and a block type (ANTEX 1.4)."""
    s = serial[:3]
    return len(s) == 3 and s[0] in "GRECJSI" and s[1:].isdigit() and (
        ant_type.startswith(("BLOCK", "GLONASS", "GALILEO", "BEIDOU", "QZSS", "IRNSS")))


def _frequency(lines, i, path, code, zen, dazi) -> tuple[int, FrequencyModel]:
    start = i
    pco = None
    noazi = None
    rows: list[tuple[float, np.ndarray]] = []
    nz = len(zen)
    while i < len(lines):
        line = lines[i]
        label = _label(line)
        ln = i + 1
        if label == "NORTH / EAST / UP":
            v = _floats(line[:30], path, ln, "NORTH / EAST / UP")
            if len(v) != 3:
                raise AntexError(f"{path}:{ln}: NORTH / EAST / UP needs three values")
            pco = np.array(v) * MM_TO_M
        elif label == "END OF FREQUENCY":
            if pco is None or noazi is None:
                raise AntexError(f"{path}:{start}: frequency {code} without NORTH / EAST / UP or NOAZI")
            if dazi > 0:
                az_expected = np.arange(0.0, 360.0 + dazi / 2, dazi)
                az = np.array([r[0] for r in rows])
                if len(az) != len(az_expected) or not np.allclose(az, az_expected):
                    raise AntexError(f"{path}:{start}: frequency {code}: azimuth rows {len(az)}, expected "
                                     f"{len(az_expected)} (DAZI {dazi})")
                return i + 1, FrequencyModel(pco, zen, noazi, az, np.array([r[1] for r in rows]))
            return i + 1, FrequencyModel(pco, zen, noazi)
        elif label in ("START OF FREQUENCY", "END OF ANTENNA"):
            raise AntexError(f"{path}:{ln}: {label} inside frequency {code} (line {start - 1})")
        elif line.startswith("   NOAZI"):
            v = _floats(line[8:], path, ln, "NOAZI")
            if len(v) != nz:
                raise AntexError(f"{path}:{ln}: NOAZI has {len(v)} values, ZEN1 / ZEN2 / DZEN gives {nz}")
            noazi = np.array(v) * MM_TO_M
        elif not label and line.strip():
            v = _floats(line, path, ln, "PCV row")
            if len(v) != nz + 1:
                raise AntexError(f"{path}:{ln}: PCV row has {len(v) - 1} values, ZEN1 / ZEN2 / DZEN gives {nz}")
            rows.append((v[0], np.array(v[1:]) * MM_TO_M))
        i += 1
    raise AntexError(f"{path}:{start}: frequency {code} without END OF FREQUENCY")


def antennas_for(antex: AntexFile, types: dict[str, str]) -> tuple[dict[str, ReceiverAntenna], list[str]]:
    """Per station its calibration from RINEX/RTCM antenna types {station: 'TYPE            RDOM'}; notes say
    what was not found (left uncorrected) or fell back to radome NONE."""
    out: dict[str, ReceiverAntenna] = {}
    notes = []
    for name, t in types.items():
        ant_name, dome = split_antenna_type(t or "")
        if not ant_name or ant_name == NULL_ANTENNA:
            notes.append(f"{name}: antenna {ant_name or 'unknown'!s}: no phase-centre correction")
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ant = antex.receiver(ant_name, dome)
        if ant is None:
            notes.append(f"{name}: antenna {ant_name} {dome} not in {Path(antex.path).name}: no phase-centre "
                         "correction")
            continue
        if ant.radome_fallback:
            notes.append(f"{name}: {ant_name} with radome {dome} not calibrated: radome {NO_RADOME}'s values")
        out[name] = ant
    return out, notes


__all__ = ["AntennaSetup", "AntexError", "AntexFile", "FrequencyModel", "NULL_ANTENNA", "ReceiverAntenna", "antennas_for",
           "read_antex", "split_antenna_type"]
