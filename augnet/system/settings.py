"""Settings of `augnet up`: every field checked, an invalid one named in the error."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from augnet.centre.vrs_admission import AdmissionConfig, check_config
from augnet.options import OptionError

DEFAULT_DB_URL = "sqlite:///augnet.db"
DEFAULT_CASTER_PORT = 2101  # IANA-registered NTRIP port
DEFAULT_CONSOLE_PORT = 8000
# A live run simulates this long when no --duration is given (the scenario's world is built for the
# whole window up front: at 1 Hz, 3 h is ~10,800 epochs per receiver, seconds to build).
DEFAULT_LIVE_WINDOW_S = 3 * 3600.0
# Trains that run the full onboard core inside the one process: each costs ~10 ms of CPU per epoch.
# Thousands of trains are the load test's job (`augnet loadtest trains`: clients sending GGA).
MAX_LIVE_TRAINS = 20
START_MARGIN_S = 3.0  # the live scenario starts this long after `up` begins (world build, connections)


class SettingsError(ValueError):
    def __init__(self, field_name: str, message: str):
        super().__init__(f"{field_name}: {message}")
        self.field = field_name


@dataclass
class SystemSettings:
    scenario: str = "demo"
    trains: int | None = None  # None: the scenario's own trains
    duration_s: float | None = None  # None: until Ctrl-C (or the live window ends)
    db_url: str = DEFAULT_DB_URL
    host: str = "127.0.0.1"
    caster_port: int = DEFAULT_CASTER_PORT
    console_port: int = DEFAULT_CONSOLE_PORT
    bus_url: str = ""  # "" in-process; nats://host:port for JetStream
    rbc: bool = True
    view: bool = True
    report_path: Path | None = None
    state_path: Path | None = Path("augnet-up.json")  # where tools find the URLs and credentials
    admin_password: str = ""  # "" -> a random one, written to the state file (0600)
    # VRS service area (augnet/centre/service_area.py): max distance from the nearest station [km] (None:
    # the network's largest station spacing) and what a client outside gets ("refuse" or "nearest")
    service_radius_km: float | None = None
    outside_area: str = "refuse"
    # when satellites the network newly corrects enter each train's VRS (docs/options/vrs.md; `--admission ...`)
    admission: AdmissionConfig = field(default_factory=AdmissionConfig)

    def validate(self) -> "SystemSettings":
        if self.trains is not None and not 0 <= self.trains <= MAX_LIVE_TRAINS:
            raise SettingsError("trains", f"must be 0..{MAX_LIVE_TRAINS} (each runs the full onboard core in this "
                                          f"process); load thousands with `augnet loadtest trains`")
        if self.duration_s is not None and not 0 < self.duration_s <= 7 * 86400:
            raise SettingsError("duration", "must be > 0 s and at most a week")
        for name in ("caster_port", "console_port"):
            port = getattr(self, name)
            if not 0 <= port <= 65535:
                raise SettingsError(name.replace("_", "-"), f"{port} is not a TCP port")
        if self.caster_port and self.caster_port == self.console_port:
            raise SettingsError("console-port", "must differ from the caster port")
        if not self.db_url or "://" not in self.db_url:
            raise SettingsError("db", f"{self.db_url!r} is not a database URL (e.g. sqlite:///augnet.db)")
        if self.bus_url and not self.bus_url.startswith("nats://"):
            raise SettingsError("bus", f"{self.bus_url!r}: expected nats://host:port or empty (in-process)")
        if self.service_radius_km is not None and not 0 < self.service_radius_km <= 20_000:
            raise SettingsError("service-radius-km", "must be > 0 and at most 20,000 km (half the Earth)")
        if self.outside_area not in ("refuse", "nearest"):
            raise SettingsError("outside-area", f"{self.outside_area!r}: expected refuse or nearest")
        try:
            check_config(self.admission)
        except OptionError as exc:
            raise SettingsError("admission", str(exc)) from None
        return self

    def area(self):
        """The service area of the centre's VRS (`AreaConfig`)."""
        from augnet.centre.service_area import AreaConfig

        radius = None if self.service_radius_km is None else self.service_radius_km * 1000.0
        return AreaConfig(max_distance_m=radius, outside=self.outside_area)
