"""GGA fuzz, end to end (issue 19): every field at extreme values, other hemispheres, poles, malformed
sentences. The parser answers each with a fix or one documented class (docs/gga.md), the centre never
raises, and a position outside the service area gets a refusal the client can read, and one alarm."""

from __future__ import annotations

import io
import json
import math
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pyrtcm import RTCMReader

from augnet.centre.engine import SUBJECT_ALARMS, CentreEngine, CentreStreamFactory, Session
from augnet.centre.service_area import AREA_ALARM_KIND, AreaAnswer, AreaConfig, ServiceArea
from augnet.gnss.geometry import ecef_to_geodetic
from augwire.errors import StreamRefused
from augwire.positions import MAX_HEIGHT_M, MIN_HEIGHT_M
from ntrip_caster.config import MountConfig
from ntrip_caster.embedded import CasterThread
from ntrip_caster.gga import GgaFix, check_gga, format_gga, nmea_checksum, parse_gga

from .helpers import make_config, open_client, read_all

# catnet's three 30 s stations: their RINEX headers' approximate positions (ECEF, m)
STATIONS = {"CREU": np.array([4715420.3054, 273177.8809, 4271946.7957]),
            "EBRE": np.array([4833520.1197, 41537.2015, 4147461.6263]),
            "GARR": np.array([4796983.5767, 160309.1177, 4187340.3773])}
INSIDE = (41.39, 2.11, 100.0)  # Barcelona, by UPC1 (20 km from GARR)
# classes a GGA is answered with (docs/gga.md)
CLASSES = {"malformed", "checksum", "no fix", "out of range"}

VALID = [b"GNGGA", b"123519.00", b"4123.4000", b"N", b"00206.6000", b"E", b"4", b"12", b"0.9",
         b"50.000", b"M", b"49.500", b"M", b"1.0", b"0031"]


def sentence(fields: list[bytes]) -> bytes:
    body = b",".join(fields)
    return b"$%b*%02X\r\n" % (body, nmea_checksum(body))


def with_field(i: int, value: bytes) -> bytes:
    f = list(VALID)
    f[i] = value
    return sentence(f)


def cls(answer) -> str:
    return "fix" if isinstance(answer, GgaFix) else answer.split(":")[0]


# (field index, value, expected class or "fix")
FIELD_CASES = [
    (1, b"235960.99", "fix"), (1, b"240000", "out of range"), (1, b"126000", "out of range"), (1, b"", "fix"),
    (1, b"1e5", "out of range"),
    (2, b"9000.0000", "fix"), (2, b"8954.0000", "fix"), (2, b"9000.0001", "out of range"),
    (2, b"4160.0000", "out of range"), (2, b"nan", "out of range"), (2, b"inf", "out of range"),
    (2, b"1e308", "out of range"), (2, b"-4123.4", "out of range"), (2, b"", "no fix"),
    (3, b"S", "fix"), (3, b"X", "out of range"), (3, b"", "out of range"),
    (4, b"18000.0000", "fix"), (4, b"18000.0001", "out of range"), (4, b"17959.9999", "fix"),
    (4, b"1_0206.6", "out of range"), (4, b"", "no fix"),
    (5, b"W", "fix"), (5, b"N", "out of range"),
    (6, b"0", "no fix"), (6, b"", "no fix"), (6, b"1", "fix"), (6, b"8", "fix"), (6, b"9", "out of range"),
    (6, b"-1", "out of range"), (6, b"99999999999", "out of range"),
    (7, b"00", "fix"), (7, b"99", "fix"), (7, b"100", "out of range"), (7, b"-3", "out of range"),
    (7, b"", "fix"),
    (8, b"99.99", "fix"), (8, b"100.0", "out of range"), (8, b"nan", "out of range"), (8, b"-1", "out of range"),
    (8, b"", "fix"),
    (9, b"1e308", "out of range"), (9, b"-1e308", "out of range"), (9, b"inf", "out of range"),
    (9, b"nan", "out of range"), (9, b"10001", "out of range"), (9, b"-1000.5", "out of range"),
    (9, b"8848.86", "fix"), (9, b"-430", "fix"), (9, b"", "fix"), (9, b" 50", "out of range"),
    (10, b"F", "malformed"),
    (11, b"200.1", "out of range"), (11, b"-106.9", "fix"), (11, b"1e308", "out of range"),
    (13, b"999.9", "fix"), (13, b"1000", "out of range"), (13, b"-1", "out of range"), (13, b"", "fix"),
    (14, b"1023", "fix"), (14, b"1024", "out of range"), (14, b"abc", "out of range"),
]


@pytest.mark.parametrize("i,value,expected", FIELD_CASES)
def test_every_field_is_range_checked(i, value, expected):
    got = check_gga(with_field(i, value))
    assert cls(got) == expected, got
    if expected == "out of range":
        assert parse_gga(with_field(i, value)) is None


def test_malformed_sentences_get_their_class():
    good = sentence(VALID)
    assert isinstance(check_gga(good), GgaFix)
    assert check_gga(good.replace(b"*", b"*0")[:-4]).startswith("checksum")
    assert check_gga(good[:-4] + b"ZZ\r\n").startswith("checksum")
    assert check_gga(good[1:]).startswith("malformed")
    assert check_gga(b"$" + b"GNGGA," * 100).startswith("malformed")
    assert check_gga(sentence(VALID + [b"extra"])).startswith("malformed")
    assert check_gga(sentence(VALID[:8])).startswith("malformed")
    assert check_gga(sentence([b"GPRMC"] + VALID[1:])).startswith("malformed")
    assert check_gga(sentence([b"G1GGA"] + VALID[1:])).startswith("malformed")
    assert check_gga(b"").startswith("malformed")
    # a sentence with no checksum is accepted (RTKLIB, BKG's caster)
    assert isinstance(check_gga(b"$" + b",".join(VALID)), GgaFix)


def test_height_is_altitude_plus_separation_within_bounds():
    assert isinstance(check_gga(with_field(9, b"9900")), GgaFix)  # 9,949.5 m
    f = list(VALID)
    f[9], f[11] = b"9950", b"60"  # 10,010 m ellipsoidal
    assert cls(check_gga(sentence(f))) == "out of range"
    fix = parse_gga(sentence(VALID))
    assert fix.height_m == pytest.approx(99.5) and fix.hdop == 0.9 and fix.age_s == 1.0


@settings(max_examples=300, deadline=None)
@given(st.integers(0, 14), st.binary(max_size=24))
def test_any_bytes_in_any_field_give_a_fix_in_bounds_or_a_class(i, value):
    if b"," in value or b"*" in value:
        value = value.replace(b",", b"").replace(b"*", b"")
    got = check_gga(with_field(i, value))
    if isinstance(got, GgaFix):
        assert -90 <= got.lat_deg <= 90 and -180 <= got.lon_deg <= 180
        assert MIN_HEIGHT_M <= got.height_m <= MAX_HEIGHT_M and 1 <= got.quality <= 8
        assert 0 <= got.num_sats <= 99
        assert all(math.isfinite(v) for v in (got.lat_deg, got.lon_deg, got.height_m))
    else:
        assert cls(got) in CLASSES, got


@settings(max_examples=200, deadline=None)
@given(st.floats(allow_nan=True, allow_infinity=True), st.floats(allow_nan=True, allow_infinity=True),
       st.floats(allow_nan=True, allow_infinity=True))
def test_formatted_positions_anywhere_parse_within_bounds_or_are_refused(lat, lon, h):
    try:
        line = format_gga(lat, lon, h)
    except (ValueError, OverflowError):
        return  # format_gga is a test helper: values it cannot print are no sentence at all
    got = check_gga(line)
    assert isinstance(got, GgaFix) or cls(got) in CLASSES


# --- the centre: every class of position gets an answer, never an exception ------------------------------

POSITIONS = {  # name -> (lat, lon, h), expected engine answer
    "inside": (INSIDE, "inside"),
    "at a station": ((41.2929, 1.9140, 600.0), "inside"),
    "north pole": ((90.0, 0.0, 0.0), "outside"),
    "89.9 N": ((89.9, 2.0, 0.0), "outside"),
    "south pole": ((-90.0, 0.0, 2800.0), "outside"),
    "southern hemisphere": ((-41.39, 2.11, 100.0), "outside"),
    "western hemisphere": ((41.39, -2.11, 100.0), "outside"),  # Spain's west: 280 km from EBRE
    "antimeridian": ((41.39, 180.0, 0.0), "outside"),
    "antipode": ((-41.39, -177.89, 0.0), "outside"),
    "height 1e308": ((41.39, 2.11, 1e308), "invalid"),
    "height -1e308": ((41.39, 2.11, -1e308), "invalid"),
    "height 10.5 km": ((41.39, 2.11, 10_500.0), "invalid"),
    "height nan": ((41.39, 2.11, math.nan), "invalid"),
    "latitude inf": ((math.inf, 2.11, 0.0), "invalid"),
    "latitude 91": ((91.0, 2.11, 0.0), "invalid"),
    "longitude -181": ((41.39, -181.0, 0.0), "invalid"),
    "longitude nan": ((41.39, math.nan, 0.0), "invalid"),
    "not a number": (("41", None, 0.0), "invalid"),
}


def engine(area: AreaConfig | None = None) -> CentreEngine:
    return CentreEngine(STATIONS, 0.0, network_name="catnet", area=area)


_ENGINE: list[CentreEngine] = []


def _shared_engine() -> CentreEngine:
    """One engine for the many examples of a property test (building one costs ~10 ms)."""
    if not _ENGINE:
        _ENGINE.append(engine())
    return _ENGINE[0]


def alarms(eng: CentreEngine) -> list[dict]:
    return [json.loads(p) for s, p in eng.drain_outbox() if s == SUBJECT_ALARMS.format(network="catnet")]


def test_default_area_is_the_largest_station_spacing():
    area = ServiceArea(STATIONS)
    # CREU's nearest neighbour is GARR, 163 km (the brief's figure: 162.9 km), the largest of the three
    assert area.radius_m == pytest.approx(162_900, abs=1_500)
    assert ServiceArea({"A": STATIONS["GARR"]}).radius_m == 50_000.0


@pytest.mark.parametrize("name", list(POSITIONS))
def test_engine_answers_every_position_class(name):
    (lat, lon, h), expected = POSITIONS[name]
    eng = engine()
    got = eng.open_session("c", lat, lon, h, lambda b: None)
    if expected == "inside":
        assert isinstance(got, Session) and "c" in eng.sessions
        assert alarms(eng) == []
    else:
        assert isinstance(got, AreaAnswer) and got.kind == expected and got.reason
        assert "c" not in eng.sessions
        assert [a["kind"] for a in alarms(eng)] == [AREA_ALARM_KIND]


@settings(max_examples=300, deadline=None)
@given(st.floats(allow_nan=True, allow_infinity=True), st.floats(allow_nan=True, allow_infinity=True),
       st.floats(allow_nan=True, allow_infinity=True))
def test_engine_never_raises_on_any_float_position(lat, lon, h):
    eng = _shared_engine()
    eng.close_session("c")
    got = eng.open_session("c", lat, lon, h, lambda b: None)
    if isinstance(got, Session):
        assert np.isfinite(got.point_ecef).all()
        assert eng.area.check(lat, lon, h).kind == "inside"
    moved = eng.move_session("c", h, lat, lon)
    assert moved is None or isinstance(moved, AreaAnswer)


def test_a_session_moving_out_is_closed_and_one_alarm_per_episode_is_raised_and_cleared():
    eng = engine()
    for i in range(3):
        assert isinstance(eng.open_session(f"in{i}", *INSIDE, lambda b: None), Session)
    refused = eng.move_session("in0", 89.9, 0.0, 0.0)
    assert refused is not None and refused.kind == "outside" and "in0" not in eng.sessions
    for i in range(50):  # a client retrying, or a flood of bad positions: one alarm
        eng.open_session(f"out{i}", -41.0, 2.0, 0.0, lambda b: None)
    raised = alarms(eng)
    assert len(raised) == 1 and not raised[0]["cleared"] and "in0" in raised[0]["message"]
    assert eng.area_alarm.refusals == 51
    eng.tick(100.0)
    assert alarms(eng) == []  # held while refusals are recent
    eng.tick(100.0 + 301.0)
    cleared = alarms(eng)
    assert len(cleared) == 1 and cleared[0]["cleared"]


def test_nearest_policy_serves_the_nearest_station_and_says_so():
    eng = engine(AreaConfig(outside="nearest"))
    got = bytearray()
    handle = CentreStreamFactory(eng).open("c", "VRS", GgaFix(-41.0, 2.0, 0.0, 1, 12, "GN", b""), got.extend)
    s = eng.sessions["c"]
    np.testing.assert_allclose(s.point_ecef, STATIONS["EBRE"])
    text = [m for _, m in RTCMReader(io.BytesIO(bytes(got)))]
    assert text[0].identity == "1029" and "serving station EBRE" in text[0].DF140
    with pytest.raises(StreamRefused):  # an invalid position is never served, whatever the policy
        handle.update_position(GgaFix(41.0, 2.0, 1e308, 1, 12, "GN", b""))
    assert "c" not in eng.sessions


def test_polygon_limits_the_area():
    square = ((41.2, 2.0), (41.2, 2.4), (41.6, 2.4), (41.6, 2.0))  # around Barcelona
    area = ServiceArea(STATIONS, AreaConfig(polygon=square))
    assert area.check(*INSIDE).kind == "inside"
    assert area.check(41.2929, 1.9140, 600.0).kind == "outside"  # GARR itself lies outside the polygon
    with pytest.raises(ValueError):
        ServiceArea(STATIONS, AreaConfig(polygon=((41.0, 1.5), (41.0, 2.5))))


def test_factory_refusal_carries_an_rtcm_text_message():
    eng = engine()
    with pytest.raises(StreamRefused) as exc:
        CentreStreamFactory(eng).open("c", "VRS", GgaFix(89.9, 0.0, 0.0, 1, 12, "GN", b""), lambda b: None)
    (raw, msg), = list(RTCMReader(io.BytesIO(exc.value.data)))
    assert msg.identity == "1029" and "outside the service area" in msg.DF140
    assert "km from the nearest station CREU" in exc.value.reason


# --- through a live caster: the client reads why, and the connection ends -------------------------------

@pytest.mark.parametrize("version", [1, 2])
def test_caster_client_outside_gets_the_reason_and_a_clean_close(version):
    vrs = MountConfig("VRS", "vrs", frozenset({"trains"}), factory="unused:unused")
    eng = engine()
    with CasterThread(make_config(extra_mounts=(vrs,)), {"VRS": CentreStreamFactory(eng)}) as ct:
        c, head = open_client(ct.port, "VRS", version=version, gga=format_gga(89.9, 2.0, 0.0))
        assert b"200 OK" in head
        rest = head.partition(b"\r\n\r\n" if version == 2 else b"\r\n")[2] + read_all(c, timeout=10)
        if version == 2:
            assert rest.endswith(b"0\r\n\r\n")
            size, _, rest = rest.partition(b"\r\n")
            rest = rest[:int(size, 16)]
        (raw, msg), = list(RTCMReader(io.BytesIO(rest)))
        assert msg.identity == "1029" and "outside the service area" in msg.DF140
        c.close()
        snap = ct.caster.snapshot()
        assert snap["mounts"]["VRS"]["drops"].get("refused") == 1 and not eng.sessions


def test_caster_ignores_a_gga_with_height_1e308_and_serves_the_next_good_one():
    vrs = MountConfig("VRS", "vrs", frozenset({"trains"}), factory="unused:unused")
    eng = engine()
    bad = sentence([b"GNGGA", b"120000.00", b"4123.4000", b"N", b"00206.6000", b"E", b"1", b"12", b"1.0",
                    b"1e308", b"M", b"0", b"M", b"", b""])
    with CasterThread(make_config(extra_mounts=(vrs,)), {"VRS": CentreStreamFactory(eng)}) as ct:
        c, head = open_client(ct.port, "VRS", version=1, gga=bad)
        assert b"200 OK" in head
        deadline = time.monotonic() + 10
        while ct.caster.counters.get("gga_unusable", 0) < 1 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert ct.caster.counters["gga_unusable"] == 1 and not eng.sessions
        time.sleep(1.1)  # the caster parses one GGA a second per client
        c.sendall(format_gga(*INSIDE))
        while not eng.sessions and time.monotonic() < deadline:
            time.sleep(0.05)
        assert list(eng.sessions) and eng.encoder is not None
        c.close()
