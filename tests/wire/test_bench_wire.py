"""`augnet bench wire` runs end to end (tiny repeats here; the figures come from the command)."""

from __future__ import annotations

import json

import pytest

from augnet.bench import rtcm as bench_rtcm
from augnet.bench import wire as bench


@pytest.fixture
def tiny_repeats(monkeypatch):
    """One short repeat per case and a 20-frame stream: the run proves the wiring, not the speed."""
    for module, name, value in ((bench_rtcm, "SECONDS_PER_REPEAT", 0.002), (bench_rtcm, "REPEATS", 1),
                                (bench, "STREAM_FRAMES", 20)):
        monkeypatch.setattr(module, name, value)


def test_bench_runs_and_reports_every_case(tiny_repeats, capsys):
    bench.main(["--json"])
    result = json.loads(capsys.readouterr().out)
    assert set(result["crc_calls_per_s"]) == {f"{n} B" for n in bench.CRC_LENGTHS}
    assert all(v > 0 for row in result["crc_calls_per_s"].values() for v in row.values())
    assert all(v > 0 for v in result["frames_per_s"].values()) and "20 frames" in result["stream"]
    bench.print_table(result)
    assert "vs pyrtcm" in capsys.readouterr().out
