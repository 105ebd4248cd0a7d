"""Scenario files: the schema of a simulated world, loading, validation and the built-in scenarios.

A scenario is a YAML file (see `stations/scenarios/*.yaml` for complete examples).  Every field is
checked; an invalid file is refused with a `ScenarioError` that names the field, the value found and
what is allowed, e.g.

    scenario bad.yaml: errors.ionosphere.level = 'stormy': Input should be 'off', 'quiet', 'moderate',
    'active' or 'storm'

Physical levels carry their units in the field names.  The ionosphere and noise presets
(`quiet` / `moderate` / `active` / `storm`, `geodetic` / `train`) expand into physical numbers when the
scenario is resolved, and the resolved scenario (`Scenario.model_dump()`) is what `sim record` writes as
`scenario.json`, so a recording always says exactly which numbers made it.
"""

from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Annotated, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from augnet.gnss.signals import DEFAULT_SIGNALS, SYSTEMS, UnknownSignal, by_rinex

BUILTIN_SCENARIOS = ("demo", "baseline-10km", "network-70km", "iono-storm", "catnet-like", "alpha-beta",
                     "alpha-beta-integrity")
DEFAULT_SCENARIO = "demo"


class ScenarioError(ValueError):
    """A scenario that cannot be used: names the field, the value and what is allowed."""


class _Strict(BaseModel):
    # Unknown keys are refused: a misspelt field must not silently fall back to its default.
    model_config = ConfigDict(extra="forbid", frozen=True)


Lat = Annotated[float, Field(ge=-90.0, le=90.0)]
Lon = Annotated[float, Field(ge=-180.0, le=180.0)]
Height = Annotated[float, Field(ge=-500.0, le=9000.0)]


class Waypoint(_Strict):
    lat_deg: Lat
    lon_deg: Lon
    h_m: Height  # ellipsoidal height of the track centre line (rail level) [m]


class Blockage(_Strict):
    """A stretch of line where the sky is (partly) hidden: the receiver loses lock there."""

    kind: Literal["tunnel", "cutting", "bridge"]  # bridge = an overbridge the train passes under
    start_km: float = Field(ge=0.0)
    end_km: float = Field(ge=0.0)
    # Cuttings: wall angle seen straight across the track (less towards the track direction);
    # tunnels and bridges hide everything.
    mask_deg: float = Field(default=90.0, ge=0.0, le=90.0)

    @model_validator(mode="after")
    def _ordered(self):
        if self.end_km <= self.start_km:
            raise ValueError(f"end_km ({self.end_km}) must be greater than start_km ({self.start_km})")
        return self


class StationArea(_Strict):
    """A railway station: extra parallel (loop) tracks either side of the main line."""

    name: str
    start_km: float = Field(ge=0.0)
    end_km: float = Field(ge=0.0)
    loop_tracks: int = Field(default=2, ge=0, le=8)

    @model_validator(mode="after")
    def _ordered(self):
        if self.end_km <= self.start_km:
            raise ValueError(f"end_km ({self.end_km}) must be greater than start_km ({self.start_km})")
        return self


class Line(_Strict):
    id: str = "L1"
    waypoints: list[Waypoint] = Field(min_length=2)
    # Horizontal curves: each interior waypoint is rounded with a circular arc of this radius
    # (high-speed lines: >= 5,500 m for 300 km/h, TB 10621-2014 / TSI INF).
    curve_radius_m: float = Field(default=5000.0, ge=200.0, le=100_000.0)
    tracks: int = Field(default=2, ge=1, le=4)  # main-line tracks
    track_spacing_m: float = Field(default=4.6, ge=3.5, le=6.0)  # centre to centre
    stations: list[StationArea] = Field(default_factory=list)
    blockages: list[Blockage] = Field(default_factory=list)


class Station(_Strict):
    """A reference station: absolute position, or placed relative to the line by km and offset."""

    id: str = Field(pattern=r"^[A-Za-z0-9_\-]{1,20}$")
    station_id: int | None = Field(default=None, ge=0, le=4095)  # RTCM reference station id
    lat_deg: Lat | None = None
    lon_deg: Lon | None = None
    h_m: Height | None = None
    km: float | None = Field(default=None, ge=0.0)  # on the line: chainage of the foot point
    offset_m: float = 30.0  # left of the line (positive) or right (negative) [m]
    mast_m: float = Field(default=5.0, ge=0.0, le=100.0)  # antenna above rail level [m]
    grade: Literal["geodetic", "train"] = "geodetic"
    outages: list[tuple[float, float]] = Field(default_factory=list)  # (from_s, to_s) since start

    @field_validator("outages")
    @classmethod
    def _intervals(cls, v):
        for a, b in v:
            if not 0.0 <= a < b:
                raise ValueError(f"outage ({a}, {b}): need 0 <= from_s < to_s")
        return v

    @model_validator(mode="after")
    def _placed(self):
        absolute = [self.lat_deg, self.lon_deg, self.h_m]
        if self.km is None and any(v is None for v in absolute):
            raise ValueError("give either km (placed on the line) or lat_deg, lon_deg and h_m")
        if self.km is not None and any(v is not None for v in absolute):
            raise ValueError("give either km or lat_deg/lon_deg/h_m, not both")
        return self


class SpeedChange(_Strict):
    from_km: float = Field(ge=0.0)
    speed_kmh: float = Field(ge=0.0, le=400.0)


class Stop(_Strict):
    """A stop on a layout route: the train's head halts at `km` (its first pass there) and stands `dwell_s`."""

    km: float = Field(ge=0.0)
    dwell_s: float = Field(gt=0.0, le=86400.0)


class Train(_Strict):
    id: str = Field(pattern=r"^[A-Za-z0-9_\-]{1,20}$")
    track: int = Field(default=1, ge=1)  # main-line track number (1 = left, as seen in +km)
    start_km: float = Field(default=0.0, ge=0.0)
    direction: Literal[1, -1] = 1  # +1: increasing km
    start_speed_kmh: float = Field(default=0.0, ge=0.0, le=400.0)
    speed_kmh: float = Field(ge=0.0, le=400.0)  # line speed the driver runs at
    speed_profile: list[SpeedChange] = Field(default_factory=list)  # restrictions by km
    accel_m_s2: float = Field(default=0.5, gt=0.0, le=2.0)  # traction
    decel_m_s2: float = Field(default=0.7, gt=0.0, le=2.0)  # service brake
    antenna_height_m: float = Field(default=4.2, ge=0.0, le=6.0)  # above rail level (roof)
    grade: Literal["geodetic", "train"] = "train"
    # Odometer (stations/odometer.py): true wheel radius minus the calibrated one, relative [%] (fixed per
    # train: wear between calibrations), and the tachometer's pulses per wheel revolution.
    wheel_radius_error_pct: float = Field(default=0.0, ge=-3.0, le=3.0)
    odometer_pulses_per_rev: int = Field(default=200, ge=1, le=10_000)
    # On a track layout (Scenario.layout): the edges the train runs over, in travel order, the first one
    # from start_km in `direction` (stations/layout.py checks it against the layout's switches).
    route: list[str] = Field(default_factory=list)
    # Train data: the train's length [m] (None: augnet.onboard.position_report.DEFAULT_TRAIN_LENGTH_M), and a
    # second antenna at the rear (route trains only), `length_m` behind the head antenna along the track: the
    # two antennas at the two ends, their lever arms to the couplers neglected (train integrity, issue 16).
    length_m: float | None = Field(default=None, gt=0.0, le=1000.0)
    rear_antenna: bool = False
    stops: list[Stop] = Field(default_factory=list)  # route trains only: halts in travel order (a platform stop)


class Ionosphere(_Strict):
    """Vertical TEC field: level preset, or explicit physical numbers (which override the preset)."""

    level: Literal["off", "quiet", "moderate", "active", "storm"] = "quiet"
    vtec_tecu: float | None = Field(default=None, ge=0.0, le=300.0)  # mean vertical TEC
    gradient_tecu_per_1000km: float | None = Field(default=None, ge=0.0, le=500.0)  # large scale
    irregularity_tecu: float | None = Field(default=None, ge=0.0, le=100.0)  # medium-scale std
    irregularity_scale_km: float | None = Field(default=None, ge=10.0, le=5000.0)
    tid_amplitude_tecu: float | None = Field(default=None, ge=0.0, le=50.0)  # travelling disturbance
    tid_wavelength_km: float | None = Field(default=None, ge=20.0, le=5000.0)
    tid_period_min: float | None = Field(default=None, ge=5.0, le=600.0)
    shell_height_km: float = Field(default=350.0, ge=150.0, le=1000.0)


class Troposphere(_Strict):
    enabled: bool = True
    # Residual zenith wet delay (truth minus model), spatially correlated [m]
    wet_residual_m: float = Field(default=0.01, ge=0.0, le=0.3)
    wet_residual_scale_km: float = Field(default=150.0, ge=5.0, le=2000.0)


class OrbitClock(_Strict):
    enabled: bool = True
    orbit_error_m: float = Field(default=0.3, ge=0.0, le=20.0)  # 1-sigma radial/along/cross [m]
    clock_error_ns: float = Field(default=1.0, ge=0.0, le=100.0)  # 1-sigma satellite clock [ns]


class Noise(_Strict):
    """Thermal noise and multipath.  Zenith figures; the receiver grade picks the preset."""

    enabled: bool = True
    multipath: bool = True
    geodetic_code_m: float = Field(default=0.3, ge=0.0, le=10.0)
    geodetic_phase_m: float = Field(default=0.002, ge=0.0, le=0.05)
    train_code_m: float = Field(default=0.8, ge=0.0, le=10.0)
    train_phase_m: float = Field(default=0.004, ge=0.0, le=0.05)
    # Code noise and multipath of the second and third signals relative to the first: real L2 P(Y) tracked
    # semi-codelessly is noisier than C/A (catnet NetRS MP2/MP1 = 1.7-2.0 above 20 deg, GARR;
    # docs/simulator-calibration.md). 1 = the same as the first signal.
    second_signal_code_factor: float = Field(default=1.0, ge=0.1, le=10.0)


# A ReceiverEvents entry names receiver ids or one of these classes; a named receiver takes its entry over its class's.
RECEIVER_CLASSES = {"stations": "station", "trains": "train"}
RECEIVER_EVENT_FIELDS = ("cycle_slips_per_hour", "phase_resets_per_hour", "unflagged_slips_per_hour",
                         "data_gaps_per_hour")


class ReceiverEvents(_Strict):
    """The tracking events of some receivers in place of `errors`' own; a rate left out keeps errors' value.

    With `announced`, the receiver flags the events errors calls unflagged: its phase resets and slips carry LLI
    (loss of lock) and restart the lock time, as a rover that reports its slips does (RINEX LLI, MSM lock time
    DF407), so a rover engine resets the ambiguity instead of guessing; its gaps still carry the phase through.
    """

    receivers: list[str] = Field(min_length=1)  # receiver ids, or "stations" / "trains"
    cycle_slips_per_hour: float | None = Field(default=None, ge=0.0, le=3600.0)
    phase_resets_per_hour: float | None = Field(default=None, ge=0.0, le=3600.0)
    unflagged_slips_per_hour: float | None = Field(default=None, ge=0.0, le=3600.0)
    data_gaps_per_hour: float | None = Field(default=None, ge=0.0, le=3600.0)
    announced: bool | None = None  # None keeps the class entry's (else False)


class Errors(_Strict):
    ionosphere: Ionosphere = Ionosphere()
    troposphere: Troposphere = Troposphere()
    orbit_clock: OrbitClock = OrbitClock()
    noise: Noise = Noise()
    receiver_clock: bool = True
    cycle_slips_per_hour: float = Field(default=0.0, ge=0.0, le=3600.0)  # per receiver-satellite
    half_cycle: bool = False  # half-cycle ambiguity at the start of each arc (flagged)
    # What real receivers do without a flag (docs/simulator-calibration.md; per receiver-satellite and hour):
    # the phase re-aligned to the code on every signal (Trimble NetRS at 30 s, decision 0150), integer slips
    # with no LLI, gaps of 1-3 epochs with the phase carried through.
    phase_resets_per_hour: float = Field(default=0.0, ge=0.0, le=3600.0)
    unflagged_slips_per_hour: float = Field(default=0.0, ge=0.0, le=3600.0)
    data_gaps_per_hour: float = Field(default=0.0, ge=0.0, le=3600.0)
    # Receivers whose own events differ from the above (a rover is not a reference station; decision 0273).
    by_receiver: list[ReceiverEvents] = Field(default_factory=list)


@dataclass(frozen=True)
class ResolvedEvents:
    """One receiver's event rates [per satellite-hour] after errors.by_receiver, and whether it flags them."""

    cycle_slips_per_hour: float
    phase_resets_per_hour: float
    unflagged_slips_per_hour: float
    data_gaps_per_hour: float
    announced: bool = False


def receiver_events(errors: Errors, receivers: list[tuple[str, str]]) -> list[ResolvedEvents]:
    """Per receiver (id, kind "station" / "train", in world order): its events, errors' own unless an entry of
    errors.by_receiver names its class or, taking precedence, its id."""
    out = []
    for rid, kind in receivers:
        entries = [e for e in errors.by_receiver if any(RECEIVER_CLASSES.get(n) == kind for n in e.receivers)]
        entries += [e for e in errors.by_receiver if rid in e.receivers]
        values = {f: getattr(errors, f) for f in RECEIVER_EVENT_FIELDS}
        announced = False
        for e in entries:
            values.update({f: getattr(e, f) for f in RECEIVER_EVENT_FIELDS if getattr(e, f) is not None})
            announced = e.announced if e.announced is not None else announced
        out.append(ResolvedEvents(**values, announced=announced))
    return out


# Fault kinds injected on the truth side (docs/decisions/0252-fault-injection-campaign.md); units in the names.
FAULT_KINDS = ("satellite_clock_step", "satellite_clock_ramp", "multipath_burst", "station_outage",
               "station_coordinates", "odometer_slide", "odometer_slip")
# Faults of the train itself, judged by the train-integrity monitor (augnet.track.train_integrity), not by the
# positioning campaign of FAULT_KINDS (decision 0293).
TRAIN_FAULT_KINDS = ("train_split",)


class TrackLayout(_Strict):
    """A track layout with turnouts the trains run over (stations/layout.py): an augnet-topology/1 file
    (a built-in name such as `alpha-beta`, or a path; relative paths are taken from the scenario file's
    directory when the scenario is loaded from a file)."""

    file: str


class Fault(_Strict):
    """One injected fault, active from at_s (until until_s where the kind has an end; seconds since start).

    - satellite_clock_step: `satellite`'s true clock jumps by `step_ns` (truth minus broadcast) and stays;
    - satellite_clock_ramp: it drifts by `ramp_ns_per_s` from at_s, back to nominal at until_s (or the end);
    - multipath_burst: `receiver` (station or train id) gets `code_m` on the code and `phase_m` on the phase of
      `satellite` (or, without one, of every satellite, each with a seeded random sign) from at_s to until_s;
    - station_outage: `station` sends nothing from at_s to until_s (or the end);
    - station_coordinates: `station`'s published coordinates (RTCM 1005 and the centre's list) are off its true
      antenna position by `offset_enu_m` (east, north, up) for the whole run (at_s must be 0);
    - odometer_slide: `train`'s wheel turns `slide_fraction` slower than the train moves (braking on wet rail);
    - odometer_slip: `train`'s wheel turns `slip_fraction` faster than the train moves (spinning under traction);
    - train_split: `train`'s rear part (with the rear antenna) separates at at_s and slows at `rear_decel_m_s2`
      to a stand while the front part runs on (the train needs `rear_antenna`).
    """

    kind: Literal[FAULT_KINDS + TRAIN_FAULT_KINDS]
    at_s: float = Field(ge=0.0)  # since start
    until_s: float | None = Field(default=None, ge=0.0)
    satellite: str | None = Field(default=None, pattern=r"^[GEC][0-9]{2}$")
    station: str | None = None
    step_ns: float = 0.0
    ramp_ns_per_s: float = Field(default=0.0, ge=-1000.0, le=1000.0)  # satellite_clock_ramp [ns/s]
    receiver: str | None = None  # multipath_burst: the receiver whose antenna sees the reflections
    code_m: float = Field(default=0.0, ge=-100.0, le=100.0)  # multipath_burst: code bias [m]
    phase_m: float = Field(default=0.0, ge=-0.25, le=0.25)  # multipath_burst: phase bias [m] (< lambda/4 ~ 5 cm)
    offset_enu_m: tuple[float, float, float] = (0.0, 0.0, 0.0)  # station_coordinates: published - true [m]
    train: str | None = None  # odometer_slide / odometer_slip: the train whose wheels slide or slip
    slide_fraction: float = Field(default=0.0, ge=0.0, le=1.0)  # wheel speed lost to the slide (1: locked)
    slip_fraction: float = Field(default=0.0, ge=0.0, le=2.0)  # wheel speed gained by the slip (1: twice)
    rear_decel_m_s2: float = Field(default=0.0, ge=0.0, le=2.0)  # train_split: the separated rear's deceleration

    @model_validator(mode="after")
    def _complete(self):
        if self.kind in ("satellite_clock_step", "satellite_clock_ramp") and self.satellite is None:
            raise ValueError(f"{self.kind} needs satellite (e.g. G05)")
        if self.kind == "satellite_clock_ramp" and self.ramp_ns_per_s == 0.0:
            raise ValueError("satellite_clock_ramp needs ramp_ns_per_s != 0")
        if self.kind in ("station_outage", "station_coordinates") and self.station is None:
            raise ValueError(f"{self.kind} needs station (a station id)")
        if self.kind == "station_coordinates" and (self.at_s != 0.0 or not any(self.offset_enu_m)):
            raise ValueError("station_coordinates needs at_s = 0 (published for the whole run) and offset_enu_m")
        if self.kind == "multipath_burst":
            if self.receiver is None or self.until_s is None or not (self.code_m or self.phase_m):
                raise ValueError("multipath_burst needs receiver, until_s and code_m or phase_m")
        if self.kind in ("odometer_slide", "odometer_slip"):
            amount = self.slide_fraction if self.kind == "odometer_slide" else self.slip_fraction
            name = "slide_fraction" if self.kind == "odometer_slide" else "slip_fraction"
            if self.train is None or self.until_s is None or not amount > 0.0:
                raise ValueError(f"{self.kind} needs train, until_s and {name} > 0")
        if self.kind == "train_split" and (self.train is None or not self.rear_decel_m_s2 > 0.0):
            raise ValueError("train_split needs train and rear_decel_m_s2 > 0")
        if self.until_s is not None and self.until_s <= self.at_s and self.kind != "satellite_clock_step":
            raise ValueError(f"{self.kind}: until_s ({self.until_s}) must be after at_s ({self.at_s})")
        return self


class Scenario(_Strict):
    name: str
    description: str = ""
    seed: int = Field(default=1, ge=0, le=2**63 - 1)
    start: _dt.datetime = _dt.datetime(2026, 3, 10, 2, 0, 0)  # GPST calendar
    duration_s: float = Field(default=600.0, gt=0.0, le=7 * 86400.0)
    rate_hz: float = Field(default=1.0, gt=0.0, le=20.0)
    constellations: list[Literal["G", "E", "C"]] = Field(default_factory=lambda: list(SYSTEMS),
                                                          min_length=1)
    signals: dict[str, list[str]] = Field(default_factory=lambda: {
        "G": ["1C", "2W"], "E": ["1C", "5Q"], "C": ["2I", "6I"]})
    elevation_mask_deg: float = Field(default=10.0, ge=0.0, le=60.0)
    line: Line | None = None
    layout: TrackLayout | None = None  # trains with a route run over it instead of the line's tracks
    stations: list[Station] = Field(min_length=1)
    trains: list[Train] = Field(default_factory=list)
    errors: Errors = Errors()
    faults: list[Fault] = Field(default_factory=list)
    # Rail surface along the whole line: wet rail has less adhesion, so more wheel slip and slide (odometer).
    rail: Literal["dry", "wet"] = "dry"
    # Seconds between 1005/1006 + 1033, and between periodic ephemeris repeats, in the RTCM stream.
    rtcm_station_interval_s: float = Field(default=5.0, gt=0.0)
    rtcm_ephemeris_interval_s: float = Field(default=30.0, gt=0.0)

    @field_validator("start")
    @classmethod
    def _naive(cls, v: _dt.datetime) -> _dt.datetime:
        if v.tzinfo is not None:
            raise ValueError("start is a GPST calendar time: give it without a timezone")
        if v.year < 2000 or v.year > 2099:
            raise ValueError("start must lie in 2000-2099")
        return v

    @field_validator("signals")
    @classmethod
    def _known_signals(cls, v: dict[str, list[str]]) -> dict[str, list[str]]:
        for system, codes in v.items():
            if system not in SYSTEMS:
                raise ValueError(f"system {system!r} unknown; allowed: {', '.join(SYSTEMS)}")
            if not 1 <= len(codes) <= 3:
                raise ValueError(f"{system}: give 1 to 3 signals, got {len(codes)}")
            for code in codes:
                try:
                    sig = by_rinex(system, code)
                except UnknownSignal:
                    allowed = ", ".join(DEFAULT_SIGNALS[system])
                    raise ValueError(f"{system} signal {code!r} unknown; e.g. {allowed}") from None
                if sig.msm_id is None:
                    raise ValueError(f"{system} signal {code!r} has no RTCM MSM id")
            bands = [c[0] for c in codes]
            if len(set(bands)) != len(bands):
                raise ValueError(f"{system}: one signal per band, got {codes}")
        return v

    @model_validator(mode="after")
    def _consistent(self):
        ids = [s.id for s in self.stations] + [t.id for t in self.trains]
        dup = {i for i in ids if ids.count(i) > 1}
        if dup:
            raise ValueError(f"receiver ids must be unique; repeated: {sorted(dup)}")
        for s in self.constellations:
            if s not in self.signals:
                raise ValueError(f"constellation {s} has no entry in signals")
        for st in self.stations:
            if st.km is not None and self.line is None:
                raise ValueError(f"station {st.id} is placed by km but the scenario has no line")
        if self.trains and self.line is None and self.layout is None:
            raise ValueError("trains need a line or a layout")
        for t in self.trains:
            if self.layout is not None and not t.route:
                raise ValueError(f"train {t.id}: the scenario has a layout, give the train's route (edge ids)")
            if self.layout is None and t.route:
                raise ValueError(f"train {t.id} has a route but the scenario has no layout")
        station_ids = {s.id for s in self.stations}
        receiver_ids = station_ids | {t.id for t in self.trains}
        for f in self.faults:
            if f.receiver is not None and f.receiver not in receiver_ids:
                raise ValueError(f"fault names receiver {f.receiver!r}; receivers are {sorted(receiver_ids)}")
        for f in self.faults:
            if f.station is not None and f.station not in station_ids:
                raise ValueError(f"fault names station {f.station!r}; stations are {sorted(station_ids)}")
        train_ids = {t.id for t in self.trains}
        named: list[str] = []
        for entry in self.errors.by_receiver:
            for n in entry.receivers:
                if n not in receiver_ids and n not in RECEIVER_CLASSES:
                    raise ValueError(f"errors.by_receiver names {n!r}; receivers are {sorted(receiver_ids)}, "
                                     f"classes {sorted(RECEIVER_CLASSES)}")
            named += entry.receivers
        twice = sorted({n for n in named if named.count(n) > 1})
        if twice:
            raise ValueError(f"errors.by_receiver names {twice} in more than one entry")
        for f in self.faults:
            if f.train is not None and f.train not in train_ids:
                raise ValueError(f"fault names train {f.train!r}; trains are {sorted(train_ids)}")
        for t in self.trains:
            if t.rear_antenna and not t.route:
                raise ValueError(f"train {t.id}: a rear antenna needs a route on a layout")
            if t.stops and not t.route:
                raise ValueError(f"train {t.id}: stops need a route on a layout")
        rear = {t.id for t in self.trains if t.rear_antenna}
        for f in self.faults:
            if f.kind == "train_split" and f.train not in rear:
                raise ValueError(f"train_split names train {f.train!r}, which has no rear antenna")
        if self.line is not None:
            for t in self.trains:
                if not t.route and t.track > self.line.tracks:
                    raise ValueError(f"train {t.id} on track {t.track}, the line has {self.line.tracks}")
        return self

    @property
    def n_epochs(self) -> int:
        return int(round(self.duration_s * self.rate_hz))

    @property
    def interval_s(self) -> float:
        return 1.0 / self.rate_hz


# Ionosphere presets in physical units.  Anchors: mid-latitude quiet-day VTEC 10-30 TECU with
# large-scale gradients of a few TECU per 1000 km and medium-scale TIDs of ~0.1-0.5 TECU (Hernandez-
# Pajares et al. 2006, J. Geophys. Res. 111); storms: gradients of tens of TECU per 1000 km and
# TIDs of several TECU.  The presets are tuned so the double-differenced L1 ionosphere over a 70 km
# baseline is ~1-4 ppm (quiet, moderate) and 10-20 ppm (storm), the figures in network-rtk.md; the test
# `test_dd_ionosphere_level` measures them (stations/README.md has the table).
#
# quiet: the medium-scale irregularity field is a standard deviation of 0.2 TECU (a sinusoid of ~0.28 TECU
# amplitude; +-2 sigma = 0.8 TECU peak to peak), plus the 0.15 TECU TID. Published quiet-day medium-scale
# structure at mid latitudes: MSTIDs of ~0.1-0.5 TECU (Hernandez-Pajares et al. 2006); 0.2-0.8 TECU for the
# terminator-generated MSTIDs of quiet 2005 days over North America (wavelength 300 +- 150 km); dominant
# peak-to-peak 0.08-1.5 TECU over North Africa on Kp <= 3 days 2008-2016 (Oluwadare et al., Pure Appl.
# Geophys. 179, 2022). The SAPOS ionospheric index I95 (95 % of the per-satellite ionospheric
# area-correction gradients, ppm on L1) reads its DD level as undisturbed: "ideal values around 1 ppm, should
# not exceed 4" (SAPOS Baden-Wuerttemberg); 0-2 undisturbed, 2-4 slightly disturbed, 4-8 strongly (LGLN,
# SAPOS Niedersachsen). stations/README.md has the DD levels each preset gives;
# docs/decisions/0011-quiet-ionosphere-preset.md why quiet is this one.
# moderate: irregularities 0.6 TECU standard deviation (+-2 sigma = 2.4 TECU peak to peak, above the largest
# quiet-day MSTIDs above, and everywhere all the time): the "slightly disturbed" I95 class, and the
# "moderate (up to 4 ppm)" days of the Norwegian CPOS interpolation study (Ouassou et al., Int. J. Navig.
# Obs. 2015, 60-70 km spacing).
IONOSPHERE_PRESETS: dict[str, dict[str, float]] = {
    "off": dict(vtec_tecu=0.0, gradient_tecu_per_1000km=0.0, irregularity_tecu=0.0,
                irregularity_scale_km=300.0, tid_amplitude_tecu=0.0, tid_wavelength_km=300.0,
                tid_period_min=40.0),
    "quiet": dict(vtec_tecu=15.0, gradient_tecu_per_1000km=4.0, irregularity_tecu=0.2,
                  irregularity_scale_km=400.0, tid_amplitude_tecu=0.15, tid_wavelength_km=250.0,
                  tid_period_min=40.0),
    "moderate": dict(vtec_tecu=15.0, gradient_tecu_per_1000km=4.0, irregularity_tecu=0.6,
                     irregularity_scale_km=400.0, tid_amplitude_tecu=0.15, tid_wavelength_km=250.0,
                     tid_period_min=40.0),
    "active": dict(vtec_tecu=30.0, gradient_tecu_per_1000km=12.0, irregularity_tecu=1.5,
                   irregularity_scale_km=300.0, tid_amplitude_tecu=0.5, tid_wavelength_km=200.0,
                   tid_period_min=30.0),
    "storm": dict(vtec_tecu=60.0, gradient_tecu_per_1000km=25.0, irregularity_tecu=3.0,
                  irregularity_scale_km=250.0, tid_amplitude_tecu=1.2, tid_wavelength_km=200.0,
                  tid_period_min=25.0),
}


def resolve_ionosphere(iono: Ionosphere) -> dict[str, float]:
    """The physical numbers of an ionosphere: the preset, overridden by any explicit field."""
    out = dict(IONOSPHERE_PRESETS[iono.level])
    for key in out:
        value = getattr(iono, key)
        if value is not None and iono.level != "off":
            out[key] = float(value)
    out["shell_height_km"] = iono.shell_height_km
    return out


def _format_error(source: str, exc: ValidationError, data: object) -> str:
    lines = []
    for err in exc.errors():
        loc = ".".join(str(p) for p in err["loc"]) or "(top level)"
        value = err.get("input")
        if err["type"] == "missing":
            lines.append(f"{loc}: missing (required)")
            continue
        if err["type"] == "extra_forbidden":
            lines.append(f"{loc} = {value!r}: unknown field (misspelt?)")
            continue
        shown = repr(value)
        if isinstance(value, dict):
            shown = "{...}"
        elif len(shown) > 80:
            shown = shown[:77] + "..."
        lines.append(f"{loc} = {shown}: {err['msg']}")
    return f"scenario {source}: " + "; ".join(lines)


def parse_scenario(data: object, source: str = "<dict>") -> Scenario:
    """Validate a mapping (from YAML or JSON) into a Scenario, or raise ScenarioError."""
    if not isinstance(data, dict):
        raise ScenarioError(f"scenario {source}: top level must be a mapping, got {type(data).__name__}")
    try:
        return Scenario.model_validate(data)
    except ValidationError as exc:
        raise ScenarioError(_format_error(source, exc, data)) from None


def load_scenario(name_or_path: str | Path) -> Scenario:
    """A built-in scenario by name (`demo`, ...) or a YAML file by path."""
    text: str
    source = str(name_or_path)
    if str(name_or_path) in BUILTIN_SCENARIOS:
        text = resources.files("stations.scenarios").joinpath(f"{name_or_path}.yaml").read_text()
    else:
        path = Path(name_or_path)
        if not path.is_file():
            raise ScenarioError(f"scenario {source}: no such file, and not a built-in "
                                f"({', '.join(BUILTIN_SCENARIOS)})")
        text = path.read_text()
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ScenarioError(f"scenario {source}: not valid YAML: {exc}") from None
    sc = parse_scenario(data, source)
    if sc.layout is not None and str(name_or_path) not in BUILTIN_SCENARIOS:
        f = Path(sc.layout.file)
        if not f.is_absolute() and (Path(name_or_path).parent / f).is_file():
            sc = sc.model_copy(update={"layout": TrackLayout(file=str(Path(name_or_path).parent / f))})
    return sc


def resolved_dict(scenario: Scenario) -> dict:
    """The scenario as written to scenario.json: every default filled, presets expanded."""
    out = scenario.model_dump(mode="json")
    out["errors"]["ionosphere_resolved"] = resolve_ionosphere(scenario.errors.ionosphere)
    return out
