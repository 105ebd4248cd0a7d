"""The load generator end to end at a small size: it spawns our caster, measures, reports JSON."""

from __future__ import annotations


import pytest
from typer.testing import CliRunner

from augwire.rtcm_framing import split_frames as split_rtcm3_frames
from ntrip_caster.loadtest import (LOADTEST_MESSAGE_TYPE, FrameCheck, LoadSettings, app, epoch_frame,
                                   run_load)


def test_epoch_frames_are_valid_rtcm():
    f = epoch_frame(7, 123456789, 1000)
    assert split_rtcm3_frames(b"xx" + f) == [f] and len(f) == 1006
    assert int.from_bytes(f[3:5], "big") >> 4 == LOADTEST_MESSAGE_TYPE
    check = FrameCheck()
    assert check.check(7, f) and check.check(7, f)
    assert not check.check(7, f[:-1] + bytes([f[-1] ^ 1]))  # differs from the first copy
    assert not FrameCheck().check(8, f[:-1] + bytes([f[-1] ^ 1]))  # bad CRC


@pytest.mark.slow
@pytest.mark.parametrize("mode,source_version", [("static", 1), ("nearest", 2), ("vrs", 1)])
def test_small_load_run(mode, source_version):
    """static: one shared fan-out; nearest: GGA picks the base; vrs: GGA opens one stream per
    client through the stream factory (relay) -- all three deliver every epoch, byte-checked."""
    r = run_load(LoadSettings(clients=60, epochs=3, rate_hz=4.0, processes=2, gga=mode == "nearest",
                              vrs=mode == "vrs", source_version=source_version, warmup_epochs=2))
    assert r["settings"]["vrs"] == (mode == "vrs")
    assert (r["requested"], r["connected"], r["complete"]) == (60, 60, 60)
    assert r["lost_epochs"] == 0 and r["bad_frames"] == 0 and r["junk_bytes"] == 0
    assert r["samples"] == 180
    lat = r["latency_ms"]
    assert 0 < lat["p50"] <= lat["p90"] <= lat["p99"] <= lat["max"] < 2000
    assert r["caster_cpu_percent"] is not None and r["caster_rss_mb"] > 10
    assert r["statuses"] == {"ICY 200 OK": 30, "HTTP/1.1 200 OK": 30}
    assert r["caster_fanout"]["drops"] == {}


def test_cli_rejects_bad_options():
    out = CliRunner().invoke(app, ["run", "--clients", "0"])
    assert out.exit_code == 2


@pytest.mark.slow
def test_external_target_path():
    """`--target host:port --caster-pid` (how Millipede is measured): here our own caster in a
    thread plays the external one, with a password-protected source and reader."""
    import os

    from ntrip_caster.embedded import CasterThread

    from .helpers import STATION_PW, TRAIN_PW, make_config

    with CasterThread(make_config()) as ct:
        r = run_load(LoadSettings(clients=20, epochs=2, rate_hz=4.0, processes=1,
                                  target=f"127.0.0.1:{ct.port}", caster_pid=os.getpid(),
                                  source_mount="BASE01", source_password=STATION_PW,
                                  mount="BASE01", user="train1", password=TRAIN_PW,
                                  label="external"))
    assert r["label"] == "external" and r["caster_fanout"] is None
    assert (r["connected"], r["complete"], r["lost_epochs"], r["bad_frames"]) == (20, 20, 0, 0)
    assert r["caster_rss_mb"] > 0
