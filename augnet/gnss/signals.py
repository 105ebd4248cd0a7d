"""One table of the signals augnet uses: system, band, frequency, wavelength, RINEX code, RTCM MSM id.

Sources: RINEX 3.04 Table 4-6 (observation codes) and frequencies (IS-GPS-200, IS-GPS-705,
Galileo OS SIS ICD, BDS-SIS-ICD B1I/B3I/B1C/B2a); RTCM 10403.3 Tables 3.5-91 (GPS),
3.5-100 (Galileo) and 3.5-106 (BeiDou) for the MSM signal ids (1-based bit positions of the
32-bit signal mask, MSB = id 1).
"""

from __future__ import annotations

from dataclasses import dataclass

from augnet.gnss.constants import SPEED_OF_LIGHT_M_S

# Carrier frequencies [Hz]
FREQ_L1_HZ = 1575.42e6  # GPS L1, Galileo E1, BDS B1C
FREQ_L2_HZ = 1227.60e6  # GPS L2
FREQ_L5_HZ = 1176.45e6  # GPS L5, Galileo E5a, BDS B2a
FREQ_E5B_HZ = 1207.14e6  # Galileo E5b, BDS B2b / B2I
FREQ_E5_HZ = 1191.795e6  # Galileo E5 AltBOC
FREQ_E6_HZ = 1278.75e6  # Galileo E6
FREQ_B1I_HZ = 1561.098e6  # BDS B1I
FREQ_B3I_HZ = 1268.52e6  # BDS B3I

SYSTEMS = ("G", "E", "C")  # RINEX system letters: GPS, Galileo, BeiDou
SYSTEM_NAMES = {"G": "GPS", "E": "Galileo", "C": "BeiDou"}


@dataclass(frozen=True)
class Signal:
    system: str  # RINEX system letter
    name: str  # conventional name, e.g. "L1C", "E5aQ", "B1I"
    band: str  # RINEX band digit as a string, e.g. "1", "2", "5", "7", "6"
    freq_hz: float
    rinex_code: str  # two characters after the observable type, e.g. "1C" in C1C/L1C
    msm_id: int | None  # RTCM MSM signal id (1..32), None where MSM defines none

    @property
    def wavelength_m(self) -> float:
        return SPEED_OF_LIGHT_M_S / self.freq_hz


def _s(system, name, freq, code, msm_id):
    return Signal(system, name, code[0], freq, code, msm_id)


SIGNALS: tuple[Signal, ...] = (
    # GPS
    _s("G", "L1C", FREQ_L1_HZ, "1C", 2),
    _s("G", "L1P", FREQ_L1_HZ, "1P", 3),
    _s("G", "L1W", FREQ_L1_HZ, "1W", 4),
    _s("G", "L2C", FREQ_L2_HZ, "2C", 8),
    _s("G", "L2P", FREQ_L2_HZ, "2P", 9),
    _s("G", "L2W", FREQ_L2_HZ, "2W", 10),
    _s("G", "L2S", FREQ_L2_HZ, "2S", 15),
    _s("G", "L2L", FREQ_L2_HZ, "2L", 16),
    _s("G", "L2X", FREQ_L2_HZ, "2X", 17),
    _s("G", "L5I", FREQ_L5_HZ, "5I", 22),
    _s("G", "L5Q", FREQ_L5_HZ, "5Q", 23),
    _s("G", "L5X", FREQ_L5_HZ, "5X", 24),
    _s("G", "L1S", FREQ_L1_HZ, "1S", 30),
    _s("G", "L1L", FREQ_L1_HZ, "1L", 31),
    _s("G", "L1X", FREQ_L1_HZ, "1X", 32),
    # Galileo
    _s("E", "E1C", FREQ_L1_HZ, "1C", 2),
    _s("E", "E1A", FREQ_L1_HZ, "1A", 3),
    _s("E", "E1B", FREQ_L1_HZ, "1B", 4),
    _s("E", "E1X", FREQ_L1_HZ, "1X", 5),
    _s("E", "E1Z", FREQ_L1_HZ, "1Z", 6),
    _s("E", "E6C", FREQ_E6_HZ, "6C", 8),
    _s("E", "E6A", FREQ_E6_HZ, "6A", 9),
    _s("E", "E6B", FREQ_E6_HZ, "6B", 10),
    _s("E", "E6X", FREQ_E6_HZ, "6X", 11),
    _s("E", "E6Z", FREQ_E6_HZ, "6Z", 12),
    _s("E", "E5bI", FREQ_E5B_HZ, "7I", 14),
    _s("E", "E5bQ", FREQ_E5B_HZ, "7Q", 15),
    _s("E", "E5bX", FREQ_E5B_HZ, "7X", 16),
    _s("E", "E5I", FREQ_E5_HZ, "8I", 18),
    _s("E", "E5Q", FREQ_E5_HZ, "8Q", 19),
    _s("E", "E5X", FREQ_E5_HZ, "8X", 20),
    _s("E", "E5aI", FREQ_L5_HZ, "5I", 22),
    _s("E", "E5aQ", FREQ_L5_HZ, "5Q", 23),
    _s("E", "E5aX", FREQ_L5_HZ, "5X", 24),
    # BeiDou (RINEX 3.04: B1I is band 2, B3I band 6, B2I/B2b band 7, B1C band 1, B2a band 5)
    _s("C", "B1I", FREQ_B1I_HZ, "2I", 2),
    _s("C", "B1Q", FREQ_B1I_HZ, "2Q", 3),
    _s("C", "B1X", FREQ_B1I_HZ, "2X", 4),
    _s("C", "B3I", FREQ_B3I_HZ, "6I", 8),
    _s("C", "B3Q", FREQ_B3I_HZ, "6Q", 9),
    _s("C", "B3X", FREQ_B3I_HZ, "6X", 10),
    _s("C", "B2I", FREQ_E5B_HZ, "7I", 14),
    _s("C", "B2Q", FREQ_E5B_HZ, "7Q", 15),
    _s("C", "B2X", FREQ_E5B_HZ, "7X", 16),
    _s("C", "B2aD", FREQ_L5_HZ, "5D", 22),
    _s("C", "B2aP", FREQ_L5_HZ, "5P", 23),
    _s("C", "B2aX", FREQ_L5_HZ, "5X", 24),
    _s("C", "B2bD", FREQ_E5B_HZ, "7D", 25),
    _s("C", "B1CD", FREQ_L1_HZ, "1D", 30),
    _s("C", "B1CP", FREQ_L1_HZ, "1P", 31),
    _s("C", "B1CX", FREQ_L1_HZ, "1X", 32),
)

_BY_RINEX = {(s.system, s.rinex_code): s for s in SIGNALS}
_BY_MSM = {(s.system, s.msm_id): s for s in SIGNALS if s.msm_id is not None}
_BY_NAME = {(s.system, s.name): s for s in SIGNALS}

# The signals augnet's simulator and network engine use by default, per system (dual frequency first).
DEFAULT_SIGNALS = {
    "G": ("1C", "2W", "5Q"),
    "E": ("1C", "5Q", "7Q"),
    "C": ("2I", "6I", "1P", "5P"),
}


class UnknownSignal(KeyError):
    pass


def by_rinex(system: str, code: str) -> Signal:
    """Signal for a system letter and RINEX code ("1C", "2W", ...)."""
    try:
        return _BY_RINEX[(system, code)]
    except KeyError:
        raise UnknownSignal(f"no signal {system} {code!r} in the signals table") from None


def by_msm(system: str, msm_id: int) -> Signal:
    """Signal for a system letter and RTCM MSM signal id (1..32)."""
    try:
        return _BY_MSM[(system, msm_id)]
    except KeyError:
        raise UnknownSignal(f"no signal {system} with MSM id {msm_id}") from None


def by_name(system: str, name: str) -> Signal:
    try:
        return _BY_NAME[(system, name)]
    except KeyError:
        raise UnknownSignal(f"no signal {system} named {name!r}") from None


def frequency_hz(system: str, code: str) -> float:
    return by_rinex(system, code).freq_hz


def wavelength_m(system: str, code: str) -> float:
    return by_rinex(system, code).wavelength_m
