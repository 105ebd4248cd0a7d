"""Post-processed network RTK: reference-station RINEX files in, a virtual RINEX for one point out.

What network operators serve to surveyors: from a folder of reference-station observation files (RINEX
2.11 or 3.x, plain or gzip; or a `augnet sim record` folder) and a broadcast navigation file, the network is
solved epoch by epoch (`network.NetworkSolver`) and a virtual reference station (VRS) is synthesised at the
requested point (`vrs.synthesize`), then written as RINEX 3.04 that any RTK engine takes as its base.

Epoch alignment. Stations may record at different intervals (1-30 s), start and stop at different times,
or miss epochs. The epochs processed are the time tags at least `MIN_STATIONS_PER_EPOCH` stations share
(a 1 s station beside a 30 s one gives 30 s epochs); at each one the network solves with the stations
present and the VRS takes its nearest present station as master. `--start`/`--end` (GPS time of day of the
first epoch's day) limit the run to a span: the network starts cold at its first epoch.

Satellites in the VRS. Where the network has fixed ambiguities around the point, the VRS carries the
satellites it has corrections for (interpolated dispersive and non-dispersive DD residuals), counted per
system as a rover double-differences them (`network_satellites`): a system with fewer than
`MIN_SYSTEM_SATELLITES` corrected is left out, and while the rest give fewer than `MIN_NETWORK_DD` double
differences (no baseline fixed yet, or a network too sparse to fix, as in 30 s data over 8 minutes on
35-150 km baselines), the epoch is a single-base VRS: the master's observations moved geometrically to the
point (range, satellite clock, Earth rotation, troposphere model) without atmospheric corrections, so a rover
sees the master's ionosphere and troposphere errors (decimetres on a 35 km baseline) but a base at the point.
Satellites the network newly corrects enter at rare admission moments, all at once, every satellite flagged
loss-of-lock there (`vrs_admission.AdmissionPolicy`; `admission=off`: each enters when corrected, flagged on
its own), so that a rover without partial ambiguity resolution keeps its fix between moments; satellites the
network loses leave at once. All satellites are flagged when the master station changes (another
receiver clock and other ambiguities), and that change is a moment too.

Station coordinates come from the RINEX headers (APPROX POSITION XYZ plus ANTENNA: DELTA H/E/N) or from a
coordinates file (`read_coordinates`): one station a line, `NAME X Y Z` (ECEF metres) or
`NAME LAT LON H` (degrees, degrees, ellipsoidal metres), blank- or comma-separated, `#` starts a comment.
The network needs surveyed coordinates: header approximate positions of real stations usually are, but a
coordinates file is the way to be sure.

Antennas. With an ANTEX file (`antex=`, `augnet vrs --antex`), each station's receiver antenna is looked up by
its RINEX header's ANT # / TYPE (type and radome; radome NONE's calibration when its own is missing, said in
the notes) and its phase-centre offsets and variations are modelled (`augnet.gnss.antex`): the network's DD
residuals refer to the antenna reference points, and the VRS is written for a null antenna at the point:
RINEX ANT # / TYPE `ADVNULLANTENNA`, ANTENNA: DELTA H/E/N zero, the point being the antenna reference point
and the phase centre (no offset, no variations). That is the convention of commercial VRS services: Trimble's
`ADVNULLANTENNA` in RTCM 1007/1008/1033 tells a rover the antenna calibration is already in the observations,
so it applies its own antenna model only (use-snip.com knowledge base "What is ADVNULLANTENNA?"; EUREF mail
6566 of 2012-08-29 on the same option at reference stations). A station whose antenna is not in the file is
left uncorrected; then the header keeps an empty antenna type and a comment says so. Without an ANTEX file
nothing is modelled and the VRS carries its master's antenna (empty antenna type), as before.
Once the baselines fix, the coordinates are checked against the data of the first hours (`station_check.py`):
a station whose position disagrees by more than the check's limits stops the run with its offsets.
"""

from __future__ import annotations

import gzip
import json
import math
import os
import re
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from augnet.centre.baseline_config import BaselineConfig
from augnet.centre.network import NetworkSolver
from augnet.centre.observations import StationEpoch, from_obsdata
from augnet.centre.station_check import CheckResult, StationCheck
from augnet.centre.vrs import geometry_many, synthesize
from augnet.centre.vrs_admission import AdmissionConfig, AdmissionPolicy, fixed_somewhere
from augnet.centre.vrs_densify import densify
from augnet.centre.vrs_modes import ModeTally, select_modes, single_base_sigma_m
from augnet.gnss.antex import NULL_ANTENNA, AntexError, ReceiverAntenna, antennas_for, read_antex
from augnet.gnss.constants import SPEED_OF_LIGHT_M_S
from augnet.gnss.ephemeris import NavigationData
from augnet.gnss.geometry import ecef_to_geodetic, enu_to_ecef, geodetic_deg_to_ecef
from augnet.gnss.rinex import RinexError, read_nav, read_obs
from augnet.gnss.rinex.obs import ObsData, ObsHeader, empty_obs, to_rinex3_types, write_obs

C = SPEED_OF_LIGHT_M_S
# An epoch is processed when at least this many stations observed it: one baseline is the least a network
# solution (and so anything beyond a single-base shift) needs.
MIN_STATIONS_PER_EPOCH = 2
# A rover double-differences within each system (one reference satellite per system), so a system of n corrected
# satellites gives it n - 1 DDs; one with fewer than this gives none and is left out of a network epoch.
MIN_SYSTEM_SATELLITES = 2
# DDs (summed over the systems left) a network epoch needs, else it is single-base: 3 for a position and 2 to
# test the integers (6 satellites of one system, 7 of two, 8 of three; decisions 0007, 0160).
MIN_NETWORK_DD = 5
# Time tags of different stations are the same epoch when they agree to this [s] (RINEX writes 0.1 us).
EPOCH_MATCH_S = 1e-3
SECONDS_PER_DAY = 86_400.0
# A baseline counts as fixed at an epoch when at least this share of its DD ambiguities is fixed.
BASELINE_FIXED_SHARE = 0.5
# The summary's fixed share of DD ambiguities counts satellites this high at both stations [deg], from this long
# after the baseline's first epoch [s] (issue 14: >= 80 % on catnet's 130 and 163 km baselines after the first hour).
SUMMARY_MIN_ELEVATION_DEG = 15.0
SUMMARY_AFTER_S = 3600.0
# |value| above which a coordinate triple is ECEF metres rather than latitude/longitude degrees (no
# latitude or longitude exceeds 360 degrees; no point on Earth is within 6000 km of its centre).
ECEF_MIN_COMPONENT_M = 1.0e4
# An approximate position this close to the Earth's centre [m] is a header that does not know its position.
MIN_STATION_RADIUS_M = 6.0e6
VRS_MARKER_NAME = "VRS"
# A VRS written at intervals longer than this [s] gets the summary's hint to write it at the rover's rate: 1 Hz is
# what RTK rovers log (decision 0222: a 1 Hz rover on a 30 s base loses V95 3.5 -> 6.9 cm on catnet).
HINT_INTERVAL_S = 1.0
PROGRAM = "augnet vrs"
LLI_LOSS_OF_LOCK = 1  # RINEX LLI bit 0

# File name patterns of observation and navigation files (RINEX 2 short names end in o/n/g/p, RINEX 3
# long names in _MO/_GN/_MN/...; recordings write <id>.obs and nav.rnx). The first header line decides.
_OBS_NAME = re.compile(r"(\.\d\d[oO]|\.obs|\.rnx|\.OBS|\.RNX)(\.gz)?$")
_OBS_ONLY_NAME = re.compile(r"(\.\d\d[oO]|\.obs|\.OBS)(\.gz)?$")
_NAV_NAME = re.compile(r"(\.\d\d[nNpP]|\.nav|\.rnx|\.NAV|\.RNX)(\.gz)?$")


class PostprocessError(ValueError):
    """Bad input for post-processing, with a message naming the file or option."""


# --------------------------------------------------------------------------------------------
# input


def parse_point(text: str, what: str = "--at") -> np.ndarray:
    """`LAT,LON,H` (degrees, degrees, ellipsoidal metres) or `X,Y,Z` (ECEF metres) -> ECEF (3,)."""
    parts = [p for p in re.split(r"[,\s]+", text.strip()) if p]
    if len(parts) != 3:
        raise PostprocessError(f"{what}: expected three numbers LAT,LON,H or X,Y,Z, got {text!r}")
    try:
        v = np.array([float(p) for p in parts])
    except ValueError:
        raise PostprocessError(f"{what}: not numbers: {text!r}") from None
    if not np.isfinite(v).all():
        raise PostprocessError(f"{what}: not finite: {text!r}")
    if np.abs(v).max() > ECEF_MIN_COMPONENT_M:
        if np.linalg.norm(v) < MIN_STATION_RADIUS_M:
            raise PostprocessError(f"{what}: ECEF point {text!r} is {np.linalg.norm(v) / 1e3:.0f} km from the "
                                   "Earth's centre, not on its surface")
        return v
    lat, lon, h = v
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 360.0):
        raise PostprocessError(f"{what}: latitude {lat} / longitude {lon} out of range")
    return np.asarray(geodetic_deg_to_ecef(lat, lon, h), float).reshape(3)


def read_coordinates(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """A coordinates file: `NAME X Y Z` or `NAME LAT LON H` per line -> {NAME (upper case): ECEF (3,)}."""
    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise PostprocessError(f"coordinates file {path}: cannot read ({exc})") from None
    out: dict[str, np.ndarray] = {}
    for ln, line in enumerate(text.splitlines(), 1):
        body = line.split("#", 1)[0].strip()
        if not body:
            continue
        parts = [p for p in re.split(r"[,\s]+", body) if p]
        if len(parts) != 4:
            raise PostprocessError(f"{path}:{ln}: expected NAME X Y Z or NAME LAT LON H, got {body!r}")
        try:
            out[parts[0].upper()] = parse_point(",".join(parts[1:]), f"{path}:{ln} ({parts[0]})")
        except PostprocessError as exc:
            raise PostprocessError(str(exc)) from None
    if not out:
        raise PostprocessError(f"coordinates file {path}: no stations in it")
    return out


def _first_line(path: Path) -> str:
    opener = gzip.open if path.name.endswith(".gz") else open
    try:
        with opener(path, "rt", errors="replace") as f:
            return f.readline()
    except (OSError, EOFError):
        return ""


def _rinex_kind(path: Path) -> str | None:
    """'O' observation, 'N' navigation (GPS or mixed), or None: from the first header line."""
    line = _first_line(path)
    if "RINEX VERSION / TYPE" not in line:
        return None
    kind = line[20:21].upper()
    if kind == "O":
        return "O"
    if kind == "N":  # RINEX 3 (any system) or RINEX 2 GPS navigation
        return "N"
    return None


def station_name(path: Path, header: ObsHeader) -> str:
    """The station's name: the 4-character site of a RINEX 2 short name (`delf0010.21o` -> DELF) or RINEX 3
    long name (`DELF00NLD_R_...` -> DELF), else the file stem (`NORTH.obs` -> NORTH)."""
    name = path.name[:-3] if path.name.endswith(".gz") else path.name
    if re.fullmatch(r"[A-Za-z0-9]{4}\d{3}[A-Za-z0-9]\.\d\d[oO]", name):
        return name[:4].upper()
    if re.fullmatch(r"[A-Za-z0-9]{4}\d\d[A-Z]{3}_[A-Z]_.*", name):
        return name[:4].upper()
    return Path(name).stem or header.marker_name


@dataclass
class Station:
    name: str
    path: Path
    obs: ObsData  # RINEX 3 type names
    xyz_m: np.ndarray  # antenna reference point, ECEF
    source: str  # where the coordinates came from
    antenna_type: str = ""  # RINEX ANT # / TYPE: type (16 characters) and radome
    antenna: ReceiverAntenna | None = None  # its ANTEX calibration (None: not modelled)
    antenna_note: str = ""  # why it is not modelled, or modelled with radome NONE's values


@dataclass
class NetworkInput:
    stations: list[Station]
    nav_path: Path
    nav: NavigationData
    excluded: list[str]  # names left out, with the reason
    recording: bool


def _recording_non_stations(folder: Path) -> dict[str, str]:
    """In a `sim record` folder: receiver ids that are not reference stations (check receivers, trains)."""
    try:
        sc = json.loads((folder / "scenario.json").read_text())
    except (OSError, ValueError) as exc:
        raise PostprocessError(f"{folder / 'scenario.json'}: cannot read the recording's scenario ({exc})") from None
    out = {}
    for st in sc.get("stations", []):
        if str(st.get("id", "")).lower().startswith("check"):
            out[str(st["id"])] = "check receiver (rover), not a reference station"
    for tr in sc.get("trains", []):
        out[str(tr.get("id"))] = "train receiver, not a reference station"
    return out


def load_network(folder: str | os.PathLike, nav: str | os.PathLike | None = None,
                 coords: str | os.PathLike | None = None, exclude: tuple[str, ...] | list[str] = (),
                 antex=None) -> NetworkInput:
    """Find and read the reference stations' observation files and the navigation file of a folder; with
    `antex` (an ANTEX file's path or a read `AntexFile`) each station's antenna calibration by its header's type."""
    folder = Path(folder)
    if not folder.is_dir():
        raise PostprocessError(f"--record {folder}: not a folder")
    recording = (folder / "scenario.json").is_file()
    skip = _recording_non_stations(folder) if recording else {}
    for e in exclude:
        skip[e] = "excluded (--exclude)"
    skip_upper = {k.upper(): v for k, v in skip.items()}
    files = sorted(p for p in folder.iterdir() if p.is_file())
    obs_files = []
    for p in files:
        if not _OBS_NAME.search(p.name):
            continue
        kind = _rinex_kind(p)
        if kind == "O":
            obs_files.append(p)
        elif kind is None and _OBS_ONLY_NAME.search(p.name):
            raise PostprocessError(f"{p}: named like an observation file but not RINEX (its first line has no "
                                   "'RINEX VERSION / TYPE')")
    if nav is None:
        candidates = [p for p in files if _NAV_NAME.search(p.name) and _rinex_kind(p) == "N"]
        if not candidates:
            raise PostprocessError(f"{folder}: no RINEX navigation file found (give one with --nav)")
        nav_path = next((p for p in candidates if p.name == "nav.rnx"), candidates[0])
    else:
        nav_path = Path(nav)
        if not nav_path.is_file():
            raise PostprocessError(f"--nav {nav_path}: no such file")
    try:
        nav_data = NavigationData(read_nav(nav_path).ephemerides)
    except RinexError as exc:
        raise PostprocessError(f"navigation file: {exc}") from None
    if not len(nav_data):
        raise PostprocessError(f"navigation file {nav_path}: no GPS/Galileo/BeiDou/QZSS ephemerides")
    if not obs_files:
        raise PostprocessError(f"{folder}: no RINEX observation files (*.obs, *.rnx, *.yyo, plain or .gz)")
    table = read_coordinates(coords) if coords is not None else {}
    stations: list[Station] = []
    excluded: list[str] = []
    for p in obs_files:
        try:
            data = read_obs(p)
        except RinexError as exc:
            raise PostprocessError(str(exc)) from None
        name = station_name(p, data.header)
        marker = data.header.marker_name.strip()
        reason = skip_upper.get(name.upper()) or skip_upper.get(marker.upper())
        if not reason and data.header.marker_type.strip().upper() == "NON_PHYSICAL":
            reason = "a computed station (MARKER TYPE NON_PHYSICAL, e.g. an earlier VRS), not a reference station"
        if reason:
            excluded.append(f"{name}: {reason}")
            continue
        if any(s.name == name for s in stations):
            raise PostprocessError(f"{p}: a second observation file of station {name}")
        data = to_rinex3_types(data)
        approx = np.asarray(data.header.approx_position_m, float)
        if name.upper() in table or marker.upper() in table:
            marker_xyz = table.get(name.upper(), table.get(marker.upper()))
            source = f"coordinates file {Path(coords).name}"
        elif np.linalg.norm(approx) > MIN_STATION_RADIUS_M:
            marker_xyz, source = approx, "RINEX header"
        else:
            raise PostprocessError(f"{p}: APPROX POSITION XYZ missing or zero and {name} is not in a coordinates "
                                   "file (give --coords)")
        h, e, n = data.header.antenna_delta_hen_m
        xyz = np.asarray(marker_xyz, float) + enu_to_ecef(np.array([e, n, h], float), marker_xyz).reshape(3)
        stations.append(Station(name, p, data, xyz, source, data.header.antenna_type))
    _station_antennas(stations, antex)
    unknown = [e for e in exclude if e.upper() not in {x.split(":")[0].upper() for x in excluded}]
    if unknown:
        raise PostprocessError(f"--exclude {' '.join(unknown)}: no such station in {folder}")
    if len(stations) < MIN_STATIONS_PER_EPOCH:
        raise PostprocessError(f"{folder}: {len(stations)} reference station(s) "
                               f"({', '.join(s.name for s in stations) or 'none'}); a network needs at least "
                               f"{MIN_STATIONS_PER_EPOCH}")
    return NetworkInput(stations, nav_path, nav_data, excluded, recording)


def _station_antennas(stations: list[Station], antex) -> None:
    """Each station's calibration from the ANTEX file by its header's antenna type, and a note on one not found
    or given radome NONE's values."""
    if antex is None:
        return
    if not hasattr(antex, "receivers"):
        try:
            antex = read_antex(antex)
        except AntexError as exc:
            raise PostprocessError(f"--antex: {exc}") from None
    found, notes = antennas_for(antex, {s.name: s.antenna_type for s in stations})
    for s in stations:
        s.antenna = found.get(s.name)
        s.antenna_note = next((x for x in notes if x.startswith(f"{s.name}: ")), "")


def parse_time_of_day(text: str, what: str) -> float:
    """`HH:MM[:SS]` -> seconds of the day (GPS time, like the RINEX epochs)."""
    m = re.fullmatch(r"\s*(\d{1,2}):(\d{2})(?::(\d{2}(?:\.\d*)?))?\s*", text)
    if not m:
        raise PostprocessError(f"{what}: expected HH:MM or HH:MM:SS (GPS time of day), got {text!r}")
    h, mi, sec = int(m.group(1)), int(m.group(2)), float(m.group(3) or 0.0)
    if h > 24 or mi > 59 or sec >= 60.0 or h * 3600 + mi * 60 + sec > SECONDS_PER_DAY:
        raise PostprocessError(f"{what}: {text!r} is not a time of day")
    return h * 3600.0 + mi * 60.0 + sec


def window_epochs(times: np.ndarray, start_s: float | None, end_s: float | None) -> np.ndarray:
    """Which of the epochs (GPST seconds) fall in [start, end] given as seconds of the first epoch's day."""
    keep = np.ones(len(times), bool)
    if not len(times):
        return keep
    day0 = math.floor(times[0] / SECONDS_PER_DAY) * SECONDS_PER_DAY
    if start_s is not None:
        keep &= times >= day0 + start_s - EPOCH_MATCH_S
    if end_s is not None:
        keep &= times <= day0 + end_s + EPOCH_MATCH_S
    return keep


def align_epochs(stations: list[Station], min_stations: int = MIN_STATIONS_PER_EPOCH):
    """The epochs at least `min_stations` stations share: (times (E,), {name: (E,) row index or -1})."""
    keys = {}
    for st in stations:
        keys[st.name] = {int(round(t / EPOCH_MATCH_S)): i for i, t in enumerate(st.obs.times)
                         if st.obs.flags[i] in (0, 1, 6)}
    counts = Counter(k for ks in keys.values() for k in ks)
    common = np.array(sorted(k for k, c in counts.items() if c >= min_stations), dtype=np.int64)
    rows = {name: np.array([ks.get(int(k), -1) for k in common], dtype=int) for name, ks in keys.items()}
    return common * EPOCH_MATCH_S, rows


# --------------------------------------------------------------------------------------------
# processing


@dataclass
class BaselineSummary:
    name: str
    length_km: float
    epochs: int = 0  # epochs both stations had data and the baseline produced a solution
    fixed_share_sum: float = 0.0
    first_epoch_t: float | None = None
    first_fix_t: float | None = None  # first epoch with BASELINE_FIXED_SHARE of its DDs fixed
    last_fixed_share: float = 0.0
    last_fixed_by_system: dict = field(default_factory=dict)  # system -> (fixed, DD ambiguities) at the end

    late_fixed: int = 0  # DD ambiguities fixed above SUMMARY_MIN_ELEVATION_DEG after SUMMARY_AFTER_S
    late_count: int = 0  # DD ambiguities there

    @property
    def late_fixed_share(self) -> float | None:
        return self.late_fixed / self.late_count if self.late_count else None

    @property
    def mean_fixed_fraction(self) -> float:
        return self.fixed_share_sum / self.epochs if self.epochs else 0.0

    @property
    def time_to_first_fix_s(self) -> float | None:
        if self.first_fix_t is None or self.first_epoch_t is None:
            return None
        return self.first_fix_t - self.first_epoch_t


@dataclass
class VrsResult:
    point_ecef_m: np.ndarray
    stations: list[Station]
    excluded: list[str]
    master: str  # network master station
    vrs_masters: Counter  # epochs per VRS master station
    epochs: list[StationEpoch]  # the VRS, epoch by epoch (empty epochs left out)
    epoch_mode: list[str]  # per written epoch: 'network' or 'single-base'
    corrected_sats: list[int]  # per written epoch: satellites with network corrections it carries
    times_processed: int
    skipped_epochs: int  # processed epochs with nothing to write (master without satellites above the point)
    baselines: dict[str, BaselineSummary]
    misclosures: int = 0
    seconds_wall: float = 0.0
    station_check: CheckResult | None = None
    notes: list[str] = field(default_factory=list)
    # per written epoch: the satellites the network had corrections for around the point, carried or not
    corrected_sets: list[frozenset] = field(default_factory=list)
    admission_moments: int = 0  # epochs at which waiting satellites entered, every satellite restarted
    # per written epoch's satellites: what the VRS carries and the centre's 1-sigma (vrs_modes.py)
    mode_tally: ModeTally = field(default_factory=ModeTally)
    epoch_sigma_m: list[float] = field(default_factory=list)  # per written epoch: its largest centre 1-sigma
    # per written epoch: the VRS master and the receiver clock [s] its geometry was computed with (vrs_densify.py)
    epoch_masters: list[str] = field(default_factory=list)
    epoch_clock_s: list[float] = field(default_factory=list)
    output_interval_s: float | None = None  # the written VRS's interval when densified (None: the network's epochs)
    interpolated_epochs: int = 0  # epochs the written VRS has between the network's (vrs_densify.py)
    written_epochs: list[StationEpoch] | None = None  # the epochs written when densified (else `epochs`)

    @property
    def antennas_modelled(self) -> list[str]:
        """The stations whose antenna was modelled (ANTEX)."""
        return [s.name for s in self.stations if s.antenna is not None]

    @property
    def null_antenna(self) -> bool:
        """The VRS refers to a null antenna at the point: every station's antenna was modelled."""
        return bool(self.stations) and all(s.antenna is not None for s in self.stations)

    @property
    def network_epochs(self) -> int:
        return sum(m == "network" for m in self.epoch_mode)

    def interval_s(self) -> float | None:
        t = np.array([e.t_gpst for e in self.epochs])
        if len(t) < 2:
            return None
        d = np.round(np.diff(t), 3)
        return float(Counter(d.tolist()).most_common(1)[0][0])


def network_satellites(corrected) -> set[str]:
    """The corrected satellites a network epoch carries: each system with at least MIN_SYSTEM_SATELLITES, when
    those give at least MIN_NETWORK_DD double differences; else none (the epoch is single-base)."""
    per_system = Counter(str(s)[0] for s in corrected)
    systems = {k for k, n in per_system.items() if n >= MIN_SYSTEM_SATELLITES}
    if sum(per_system[k] - 1 for k in systems) < MIN_NETWORK_DD:
        return set()
    return {str(s) for s in corrected if str(s)[0] in systems}


def _station_clocks(net: NetworkSolver) -> dict[str, float]:
    clocks: dict[str, float] = {}
    for solver in net.solvers.values():
        clocks.setdefault(solver.name_a, solver.clock["a"])
        clocks.setdefault(solver.name_b, solver.clock["b"])
    return clocks


def single_base_epoch(master: StationEpoch, master_xyz_m, point_ecef_m, nav: NavigationData,
                      clock_s: float, antenna_m: np.ndarray | None = None) -> StationEpoch:
    """The master's observations moved geometrically to the point, no atmospheric corrections (the VRS
    synthesis of `vrs.py` with zero interpolated corrections, for every satellite). `antenna_m` (S, 2): the
    master's phase-centre correction, to refer its observations to its ARP first (a null antenna VRS)."""
    if antenna_m is not None:
        master = StationEpoch(master.station, master.t_gpst, master.sats, master.code_m + antenna_m,
                              master.phase_cyc + antenna_m * master.freq_hz / C, master.lli, master.cnr_dbhz,
                              master.freq_hz, master.codes)
    g_m, trop_m, _ = geometry_many(master.sats, master.t_gpst, clock_s, master_xyz_m, nav)
    g_v, trop_v, el_v = geometry_many(master.sats, master.t_gpst, clock_s, point_ecef_m, nav)
    shift = ((g_v - g_m) + (trop_v - trop_m))[0]  # (S,)
    use = np.isfinite(shift) & (el_v[0] > 0)
    lam = C / master.freq_hz
    code = master.code_m + shift[:, None]
    phase = master.phase_cyc + shift[:, None] / lam
    ep = StationEpoch(VRS_MARKER_NAME, master.t_gpst, master.sats, code, phase, master.lli.copy(),
                      master.cnr_dbhz, master.freq_hz, master.codes)
    return ep.subset(use)


def process(inp: NetworkInput, point_ecef_m, master: str | None = None, progress=None,
            config: BaselineConfig | None = None, start_s: float | None = None,
            end_s: float | None = None, admission: AdmissionConfig | None = None) -> VrsResult:
    """Solve the network epoch by epoch (with the engine's settings `config`, default when None) and synthesise
    the VRS at the point, newly corrected satellites entering it as `admission` says (vrs_admission.py); only the
    epochs from `start_s` to `end_s` (seconds of the first epoch's day, GPS time) when given: the network starts
    cold at the first of them."""
    t_wall = time.perf_counter()
    point = np.asarray(point_ecef_m, float).reshape(1, 3)
    stations = {s.name: s.xyz_m for s in inp.stations}
    if master is not None and master not in stations:
        raise PostprocessError(f"--master {master}: not one of the stations ({', '.join(stations)})")
    net = NetworkSolver(stations, master=master, config=config,
                        antennas={s.name: s.antenna for s in inp.stations if s.antenna is not None})
    times, rows = align_epochs(inp.stations)
    keep = window_epochs(times, start_s, end_s)
    if not keep.any():
        raise PostprocessError("--start/--end: no epoch of the stations falls in that span")
    times, rows = times[keep], {name: r[keep] for name, r in rows.items()}
    by_name = {s.name: s for s in inp.stations}
    summaries = {s.name: BaselineSummary(s.name, s.length_m / 1e3) for s in net.solvers.values()}
    epochs: list[StationEpoch] = []
    modes: list[str] = []
    n_corr: list[int] = []
    corrected_sets: list[frozenset] = []  # per processed epoch with satellites: corrected around the point
    masters: Counter = Counter()
    prev_master = None
    prev_corrected: set[str] = set()
    policy = AdmissionPolicy(admission, network_satellites)
    restarts = 0
    skipped = 0
    misclosures = 0
    tally = ModeTally()
    epoch_sigma: list[float] = []
    epoch_masters: list[str] = []
    epoch_clock: list[float] = []
    check = StationCheck(stations, {s.name: (s.name_a, s.name_b) for s in net.solvers.values()}, inp.nav)
    checked: CheckResult | None = None
    for e, t in enumerate(times):
        eps = {}
        for name, r in rows.items():
            if r[e] >= 0:
                eps[name] = from_obsdata(by_name[name].obs, int(r[e]), name)
        ne = net.update(eps, inp.nav)
        misclosures += ne.misclosures
        if checked is None:
            check.add(ne)
            if check.complete:
                checked = _judge_stations(check)
        for solver in net.solvers.values():
            res = ne.baselines[solver.name]
            bs = summaries[solver.name]
            if res is None:
                continue
            bs.epochs += 1
            bs.fixed_share_sum += res.fixed_fraction
            bs.last_fixed_share = res.fixed_fraction
            nonref = ~res.is_reference()
            systems = np.array([str(x)[0] for x in res.sats])
            bs.last_fixed_by_system = {sys_: (int((res.fixed & nonref & (systems == sys_)).sum()),
                                              int((nonref & (systems == sys_)).sum()))
                                       for sys_ in sorted(set(systems.tolist()))}
            if bs.first_epoch_t is None:
                bs.first_epoch_t = float(t)
            if t - bs.first_epoch_t >= SUMMARY_AFTER_S:
                high = nonref & (np.minimum(res.elevation_a_deg, res.elevation_b_deg) >= SUMMARY_MIN_ELEVATION_DEG)
                bs.late_fixed += int((res.fixed & high).sum())
                bs.late_count += int(high.sum())
            if bs.first_fix_t is None and res.fixed_fraction >= BASELINE_FIXED_SHARE:
                bs.first_fix_t = float(t)
        clocks = dict(getattr(ne, "clocks", None) or _station_clocks(net))
        # synthesize() needs at least one baseline solution this epoch (it indexes the network's satellite
        # columns); without one the epoch can only be single-base
        vrs = synthesize(ne, eps, point, inp.nav, clocks) if len(ne.sats) else None
        have = [n for n in eps if len(eps[n].sats)]
        if not have:
            skipped += 1
            continue
        if vrs is not None:
            vmaster = vrs.master[0]
            # a satellite counts as corrected only where a baseline fixed it (vrs_admission.fixed_somewhere)
            corrected = set(map(str, vrs.sats[vrs.corrected[0]])) & fixed_somewhere(ne)
        else:
            vmaster = min(have, key=lambda n: float(np.linalg.norm(stations[n] - point[0])))
            corrected = set()
        corrected_sets.append(frozenset(corrected))
        if prev_master is not None and vmaster != prev_master:
            policy.restart()
        decision = policy.step(float(t), corrected)
        corrected = set(decision.carried)
        if corrected:
            ep = vrs.station_epoch(0, VRS_MARKER_NAME)
            keep = np.isin(ep.sats, list(corrected))
            ep = ep.subset(keep)
            mode = "network"
        else:
            ep = single_base_epoch(eps[vmaster], stations[vmaster], point, inp.nav, clocks.get(vmaster, 0.0),
                                   ne.antenna_correction(eps[vmaster]))
            corrected = set()
            mode = "single-base"
        ep.lli = ep.lli.copy()
        if prev_master is not None and vmaster != prev_master or decision.restart:
            ep.lli |= LLI_LOSS_OF_LOCK  # another master (other clock and ambiguities), or an admission moment
        else:
            newly = np.array([str(s) in corrected and str(s) not in prev_corrected for s in ep.sats], bool)
            if prev_master is not None and newly.any():
                ep.lli[newly] |= LLI_LOSS_OF_LOCK
            lost = np.array([str(s) in prev_corrected and str(s) not in corrected for s in ep.sats], bool)
            if lost.any():
                ep.lli[lost] |= LLI_LOSS_OF_LOCK
        if not len(ep.sats):
            skipped += 1
            corrected_sets.pop()
            continue
        restarts += decision.restart
        prev_master, prev_corrected = vmaster, corrected
        # what each carried satellite is (no float model here: decision 0230) and the single-base error it has
        level = float(np.median([s_.ionosphere.level_ppm for s_ in net.solvers.values()])) if net.solvers else 0.0
        d_master = float(np.linalg.norm(stations[vmaster] - point[0]))
        sat_corr = np.isin(ep.sats, list(corrected))[None]
        sat_modes, sat_sigma = select_modes(sat_corr, single_base_sigma_m([d_master], level))
        tally.add(sat_modes[0], sat_sigma[0])
        epoch_sigma.append(float(np.max(sat_sigma[0])) if np.isfinite(sat_sigma[0]).all() else float("nan"))
        masters[vmaster] += 1
        epoch_masters.append(vmaster)
        epoch_clock.append(float(clocks.get(vmaster, 0.0)))
        epochs.append(ep)
        modes.append(mode)
        n_corr.append(len(corrected))
        if progress is not None:
            progress(e + 1, len(times))
    return VrsResult(point_ecef_m=point[0], stations=inp.stations, excluded=inp.excluded, master=net.master,
                     vrs_masters=masters, epochs=epochs, epoch_mode=modes, corrected_sats=n_corr,
                     times_processed=len(times), skipped_epochs=skipped, baselines=summaries,
                     misclosures=misclosures, seconds_wall=time.perf_counter() - t_wall,
                     station_check=checked if checked is not None else _judge_stations(check),
                     corrected_sets=corrected_sets, admission_moments=restarts, mode_tally=tally,
                     epoch_sigma_m=epoch_sigma, epoch_masters=epoch_masters, epoch_clock_s=epoch_clock)


def _judge_stations(check: StationCheck) -> CheckResult:
    """The station-coordinate check's verdict; a station the others single out stops the run: a network fixed on
    a wrong position gives every rover that error. When half the stations or more are flagged the check names no
    culprit (measured on catnet 06-09 h: all three flagged, RTKLIB static puts each within 2.4 cm of its header,
    decision 0163), so the run goes on and the summary says the coordinates are unconfirmed."""
    res = check.result()
    if res.flagged and 2 * len(res.flagged) < len(check.names):
        raise PostprocessError("station coordinates disagree with the data: " + "; ".join(res.lines()[1:])
                               + f" -- survey {', '.join(res.flagged)} again and give --coords, or leave it out "
                               "with --exclude")
    return res


# --------------------------------------------------------------------------------------------
# output


def to_obsdata(result: VrsResult, marker_name: str = VRS_MARKER_NAME) -> ObsData:
    """The VRS epochs as RINEX 3.04 observations (code, phase, C/N0 on each signal used)."""
    eps = result.epochs if result.written_epochs is None else result.written_epochs
    if not eps:
        raise PostprocessError("no VRS epoch to write: no epoch had a master station with satellites above the "
                               "point")
    sats = sorted({str(s) for ep in eps for s in ep.sats}, key=lambda s: (s[0], s[1:]))
    codes: dict[str, list[str]] = {}
    for ep in eps:
        for s, pair in zip(ep.sats, ep.codes):
            for rc in pair:
                if rc and rc not in codes.setdefault(str(s)[0], []):
                    codes[str(s)[0]].append(rc)
    obs_types = {sys_: [f"{kind}{rc}" for rc in sorted(rcs, key=lambda c: (c[0], c)) for kind in "CLS"]
                 for sys_, rcs in sorted(codes.items())}
    lat, lon, h = ecef_to_geodetic(result.point_ecef_m[None])[0]
    used = ", ".join(s.name for s in result.stations)
    masters = ", ".join(f"{m} ({n} epochs)" for m, n in result.vrs_masters.most_common())
    comments = [
        "virtual reference station (VRS) synthesised by augnet",
        f"point lat {math.degrees(lat):.8f} lon {math.degrees(lon):.8f} h {h:.3f} m",
        f"stations: {used}"[:60],
        f"network master {result.master}; VRS master {masters}"[:60],
        f"network-corrected epochs {result.network_epochs} of {len(eps)}; the rest"[:60],
        "single-base (geometric shift only, no atmosphere corr.)",
        "receiver clock and ambiguities are the VRS master's",
    ]
    comments += _antenna_comments(result)
    if result.interpolated_epochs:
        comments += [f"{result.interpolated_epochs} epochs interpolated in time between"[:60],
                     "network epochs (geometry at each epoch; vrs_densify.py)"]
    header = ObsHeader(program=PROGRAM, run_by="augnet", marker_name=marker_name, marker_type="NON_PHYSICAL",
                       observer="augnet", agency="augnet network RTK", receiver_type="AUGNET VRS",
                       receiver_version="1", antenna_type=_vrs_antenna_type(result),
                       approx_position_m=tuple(result.point_ecef_m),
                       obs_types=obs_types, signal_strength_unit="DBHZ",
                       interval_s=result.output_interval_s or result.interval_s(),
                       time_of_first_obs=eps[0].t_gpst, time_of_last_obs=eps[-1].t_gpst, time_system="GPS",
                       comments=comments)
    data = empty_obs(header, [ep.t_gpst for ep in eps], sats)
    col = {s: j for j, s in enumerate(sats)}
    for i, ep in enumerate(eps):
        for k, s in enumerate(ep.sats):
            j = col[str(s)]
            for f in range(2):
                rc = ep.codes[k, f]
                if not rc:
                    continue
                data.obs["C" + rc][i, j] = ep.code_m[k, f]
                data.obs["L" + rc][i, j] = ep.phase_cyc[k, f]
                data.lli["L" + rc][i, j] = ep.lli[k, f] & 0x7
                data.obs["S" + rc][i, j] = ep.cnr_dbhz[k, f]
    return data


def _vrs_antenna_type(result: VrsResult) -> str:
    """RINEX ANT # / TYPE of the VRS: the null antenna when every station's antenna was modelled."""
    return f"{NULL_ANTENNA:<16}NONE" if result.null_antenna else ""


def _antenna_comments(result: VrsResult) -> list[str]:
    if result.null_antenna:
        return ["antenna: null antenna at the point (station PCO/PCV",
                "removed with ANTEX); rover applies only its own model"]
    if result.antennas_modelled:
        return [f"antenna PCO/PCV modelled at {', '.join(result.antennas_modelled)} only"[:60]]
    return []


def densify_result(result: VrsResult, nav: NavigationData, interval_s: float) -> VrsResult:
    """Give the result epochs every `interval_s` between its network epochs (vrs_densify.py): what is written."""
    if not interval_s > 0:
        raise PostprocessError(f"--interval {interval_s!r}: not a positive number of seconds")
    network_interval = result.interval_s()
    if network_interval is None or interval_s >= network_interval:
        return result
    result.written_epochs, result.interpolated_epochs = densify(
        result.epochs, result.epoch_clock_s, result.epoch_masters, result.point_ecef_m, nav, interval_s,
        max_gap_s=network_interval)
    result.output_interval_s = float(interval_s)
    return result


def write_vrs(result: VrsResult, path: str | os.PathLike, marker_name: str = VRS_MARKER_NAME) -> Path:
    path = Path(path)
    try:
        write_obs(path, to_obsdata(result, marker_name))
    except OSError as exc:
        raise PostprocessError(f"--out {path}: cannot write ({exc})") from None
    return path


def summary_lines(result: VrsResult) -> list[str]:
    """What was used, what was solved and what was not, in words an operator reads."""
    lines = []
    lat, lon, h = ecef_to_geodetic(result.point_ecef_m[None])[0]
    lines.append(f"point: lat {math.degrees(lat):.7f} lon {math.degrees(lon):.7f} h {h:.2f} m")
    for s in result.stations:
        d = np.linalg.norm(s.xyz_m - result.point_ecef_m) / 1e3
        lines.append(f"station {s.name}: {len(s.obs.times)} epochs in {s.path.name}, {d:.1f} km from the point, "
                     f"coordinates from {s.source}")
    for x in result.excluded:
        lines.append(f"not used: {x}")
    if result.antennas_modelled:
        lines.append("antenna models (ANTEX): " + ", ".join(
            f"{s.name} {s.antenna_type.strip() or '?'}" for s in result.stations if s.name in result.antennas_modelled)
            + ("; VRS for a null antenna (ADVNULLANTENNA)" if result.null_antenna else ""))
    for s in result.stations:
        if s.antenna_note:
            lines.append(f"note: {s.antenna_note}")
    lines.append(f"network master {result.master}; epochs shared by >= {MIN_STATIONS_PER_EPOCH} stations: "
                 f"{result.times_processed}; VRS epochs written: {len(result.epochs)}"
                 + (f" ({result.skipped_epochs} had nothing to write)" if result.skipped_epochs else ""))
    any_fixed = False
    for b in result.baselines.values():
        ttf = b.time_to_first_fix_s
        if b.epochs == 0:
            lines.append(f"baseline {b.name} ({b.length_km:.1f} km): never solved (no common epochs with "
                         "dual-frequency data)")
            continue
        any_fixed |= b.first_fix_t is not None
        fix_txt = (f"first fix after {ttf:.0f} s" if ttf is not None
                   else f"never reached {BASELINE_FIXED_SHARE:.0%} of its ambiguities fixed")
        per_sys = ", ".join(f"{k} {v[0]}/{v[1]}" for k, v in b.last_fixed_by_system.items())
        late = (f", {b.late_fixed_share:.0%} of DD ambiguities above {SUMMARY_MIN_ELEVATION_DEG:.0f} deg fixed "
                f"after the first {SUMMARY_AFTER_S / 3600:.0f} h" if b.late_fixed_share is not None else "")
        lines.append(f"baseline {b.name} ({b.length_km:.1f} km): {b.epochs} epochs, mean fixed fraction "
                     f"{b.mean_fixed_fraction:.0%}, last {b.last_fixed_share:.0%} ({per_sys}), {fix_txt}{late}")
    if result.misclosures:
        lines.append(f"triangle misclosures (satellites voided for an epoch): {result.misclosures}")
    if result.station_check is not None:
        lines.extend(result.station_check.lines())
    n = len(result.epochs)
    net_n = result.network_epochs
    if n:
        lines.append(f"network-corrected VRS epochs: {net_n} of {n} ({net_n / n:.0%}), median "
                     f"{int(np.median([c for c in result.corrected_sats if c] or [0]))} corrected satellites; "
                     f"single-base epochs: {n - net_n}")
    if net_n == 0:
        if any_fixed:
            lines.append("baselines fixed, but never around the point with enough satellites: corrections are "
                         "single-base geometric shifts only")
        else:
            lines.append("no baseline fixed: corrections are single-base geometric shifts only (the master's "
                         "ionosphere and troposphere errors reach the rover unreduced)")
    elif net_n < n:
        first_net = result.epoch_mode.index("network")
        lines.append(f"{n - net_n} epochs are single-base geometric shifts ({first_net} before the network first "
                     "had corrections around the point, the rest later)")
    waited = sum(len(c) for c in result.corrected_sets) - sum(result.corrected_sats)
    if result.admission_moments:
        lines.append(f"admission moments (waiting satellites entered, every satellite restarted): "
                     f"{result.admission_moments}; corrected satellite-epochs not carried (waiting, or a system "
                     f"too thin): {waited}")
    lines.extend(result.mode_tally.lines())
    network_interval = result.interval_s()
    if not result.interpolated_epochs and network_interval is not None and network_interval > HINT_INTERVAL_S:
        lines.append(f"VRS written at the network's {network_interval:g} s: a faster rover holds each epoch up to "
                     f"{network_interval - 1:g} s; --interval S writes it at the rover's rate (decision 0222)")
    if result.interpolated_epochs:
        lines.append(f"VRS written every {result.output_interval_s:g} s: {len(result.written_epochs)} epochs, "
                     f"{result.interpolated_epochs} of them interpolated in time between network epochs (no "
                     "gaps bridged, no satellite across a loss of lock)")
    lines.append(f"VRS master station(s): " + ", ".join(f"{m} ({k} epochs)" for m, k in result.vrs_masters.most_common()))
    lines.append(f"processing time {result.seconds_wall:.1f} s")
    return lines


def run_vrs(record: str | os.PathLike, at: str, out: str | os.PathLike, nav=None, coords=None,
            exclude=(), master: str | None = None, marker_name: str = VRS_MARKER_NAME,
            progress=None, config: BaselineConfig | None = None, antex=None, start: str | None = None,
            end: str | None = None, admission: AdmissionConfig | None = None,
            interval: float | None = None) -> tuple[VrsResult, list[str]]:
    """The whole post-processing: read, solve, synthesise, write. Returns the result and its summary. `interval`
    [s]: write the VRS at that rate, epochs between the network's interpolated in time (a 1 Hz rover on a 30 s
    network: decision 0222); None: at the network's epochs."""
    point = parse_point(at)
    start_s = parse_time_of_day(start, "--start") if start else None
    end_s = parse_time_of_day(end, "--end") if end else None
    if start_s is not None and end_s is not None and end_s <= start_s:
        raise PostprocessError(f"--end {end} is not after --start {start}")
    inp = load_network(record, nav=nav, coords=coords, exclude=tuple(exclude), antex=antex)
    result = process(inp, point, master=master, progress=progress, config=config, start_s=start_s, end_s=end_s,
                     admission=admission)
    if interval is not None:
        densify_result(result, inp.nav, float(interval))
    write_vrs(result, out, marker_name)
    return result, summary_lines(result)
