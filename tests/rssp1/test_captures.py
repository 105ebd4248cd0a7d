"""The real captures (../shared/data/rssp1): every RSD passes CRC16, 0x0029 passes both check words,
the other senders' SIDs are recovered from two frames and then verify every frame; the CLI reports it."""

from __future__ import annotations

import subprocess
import sys

import pytest
from typer.testing import CliRunner

from rssp1.cli import app
from rssp1.config import DeviceConfig, LinkTiming
from rssp1.frames import Rsd, decode_frame
from rssp1.inspect import inspect_captures, parse_device
from rssp1.pcapng import CaptureStats, udp_datagrams
from rssp1.sid_recovery import forge_rsd_svc, recover_sid

pytestmark = pytest.mark.shared_data
SID_0029 = (0x311616DC, 0x07643EDE)  # rssp1.md
RSD_FRAMES_IN_CAPTURES = 970  # rssp1.md / PROVENANCE.md


@pytest.fixture(scope="module")
def captures(shared_data):
    paths = sorted((shared_data / "rssp1").glob("*.pcapng"))
    assert len(paths) == 2
    return paths


def test_every_rsd_passes_crc16_and_0029_passes_both_check_words(captures):
    report = inspect_captures(captures, [DeviceConfig(0x29, SID_0029)])
    assert report.rsd_total == RSD_FRAMES_IN_CAPTURES
    assert sum(s.crc16_passed for s in report.sources.values()) == RSD_FRAMES_IN_CAPTURES
    assert report.undecodable == {}
    s29 = report.sources[0x29]
    assert s29.rsd == s29.svc_passed == 221 and s29.svc_failed == 0
    assert set(report.sources) == {0x29, 0x2A, 0x2B, 0x2C, 0x2D, 0x2E}
    for source in (0x2A, 0x2B, 0x2C, 0x2D, 0x2E):
        assert report.sources[source].svc_not_checked == report.sources[source].rsd
    # a wrong SID for 0x0029 fails every frame: the check is not vacuous
    wrong = inspect_captures(captures, [DeviceConfig(0x29, (SID_0029[0] ^ 1, SID_0029[1]))])
    assert wrong.sources[0x29].svc_passed == 0 and wrong.sources[0x29].svc_failed == 221


def test_crc16_residue_check_agrees_with_the_stored_field(captures):
    from rssp1.crc import crc16
    from rssp1.frames import check_crc16

    n = 0
    for path in captures:
        for d in udp_datagrams(path):
            if d.dst_port in (50000, 50001):
                assert check_crc16(d.payload) and crc16(d.payload) == 0
                bad = bytes([d.payload[0] ^ 4]) + d.payload[1:]
                assert not check_crc16(bad) and crc16(bad) != 0
                n += 1
    assert n == RSD_FRAMES_IN_CAPTURES


def test_sids_recovered_from_two_frames_verify_every_frame(captures):
    report = inspect_captures(captures, recover=True)
    assert report.sources[0x29].sid == SID_0029
    for s in report.sources.values():
        assert s.sid_recovered and s.svc_passed == s.rsd and s.svc_failed == 0
    assert sum(s.svc_passed for s in report.sources.values()) == RSD_FRAMES_IN_CAPTURES


def test_captured_streams_replayed_through_the_receive_state_machine(captures):
    """Real traffic through Endpoint (monitor mode, local cycles from the capture timestamps, the
    field timing of 250 ms / deltaTime 3 / DelayTime 3): every machine-A path is accepted frame for
    frame; machine B of 0x002A skipped 3 cycles once (TC +4) and its receiver's link drops once."""
    report = inspect_captures(captures, recover=True, timing=LinkTiming(0.25, 3, 4, 3))
    assert len(report.paths) == 18
    assert sum(p.frames for p in report.paths) == RSD_FRAMES_IN_CAPTURES
    for p in report.paths:
        if (p.source, p.machine) == (0x2A, "B"):
            assert p.link_downs == {"timeout": 1} and p.accepted == p.frames == 19
        else:
            assert p.accepted == p.frames and p.link_downs == {} and p.dropped == {}, p
    # Stricter limits (deltaTime 2, DelayTime 2) also break 0x002A B at each of its four TC +2 steps,
    # while 0x0029 B, which never skipped a cycle, stays up: the replay sees exactly the capture's gaps.
    strict = inspect_captures(captures, recover=True, timing=LinkTiming(0.25, 2, 4, 2))
    b29 = next(p for p in strict.paths if (p.source, p.machine) == (0x29, "B"))
    b2a = next(p for p in strict.paths if (p.source, p.machine) == (0x2A, "B"))
    assert b29.link_downs == {} and sum(b2a.link_downs.values()) >= 4  # the four TC +2 steps too


def test_forged_frame_from_recovered_identity_verifies(captures):
    frames = sorted(
        {f.tc: f for p in captures for d in udp_datagrams(p) if d.dst_port == 50000
         for f in [decode_frame(d.payload)] if isinstance(f, Rsd) and f.source == 0x2A}.values(),
        key=lambda f: f.tc,
    )
    (identity,) = recover_sid(frames[0], frames[1])
    # The masquerade: a frame at a later TC with data the sender never sent carries the very check
    # words the real sender would have produced (compare with a real later frame's data).
    real = frames[10]
    assert forge_rsd_svc(identity, real.tc, real.data) == real.svc
    assert forge_rsd_svc(identity, real.tc, b"forged") != real.svc


def test_cli_inspect_prints_per_source_counts(captures):
    result = CliRunner().invoke(app, ["inspect", *map(str, captures), "--device", "0x29:0x311616DC,0x07643EDE"])
    assert result.exit_code == 0, result.output
    line = next(l for l in result.output.splitlines() if l.strip().startswith("0x0029"))
    assert line.split()[1:8] == ["221", "221", "0", "0", "221", "221", "0"]
    assert "RSD frames: 970" in result.output
    bad = CliRunner().invoke(app, ["inspect", str(captures[0]), "--device", "0x29:nonsense"])
    assert bad.exit_code != 0


@pytest.mark.slow
def test_python_dash_m_entry_point(captures):
    out = subprocess.run(
        [sys.executable, "-m", "rssp1", "inspect", str(captures[1]), "--recover-sids"],
        capture_output=True, text=True, timeout=120, check=True,
    ).stdout
    assert "(recovered)" in out and "0x311616dc,0x07643ede" in out


def test_truncated_and_garbage_captures_do_not_crash(captures, tmp_path):
    whole = captures[1].read_bytes()
    cut = tmp_path / "cut.pcapng"
    cut.write_bytes(whole[: len(whole) // 2 + 13])
    stats = CaptureStats()
    datagrams = list(udp_datagrams(cut, stats))
    assert 0 < len(datagrams) and stats.damaged_blocks == 1
    junk = tmp_path / "junk.pcapng"
    junk.write_bytes(b"not a capture at all")
    with pytest.raises(ValueError):
        list(udp_datagrams(junk))


def test_parse_device():
    d = parse_device("0x29:0x311616DC,0x07643EDE")
    assert d.address == 0x29 and d.sid == SID_0029 and d.timestamp_seed == SID_0029
    assert parse_device("41:1,2:3,4").timestamp_seed == (3, 4)
    with pytest.raises(ValueError):
        parse_device("0x29")
    with pytest.raises(ValueError):
        parse_device("0x29:1,2,3")
