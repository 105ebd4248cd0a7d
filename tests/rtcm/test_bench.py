"""The RTCM benchmark runs end to end (tiny repeats here; the figures come from `augnet bench rtcm`)."""

from __future__ import annotations

import json

from augnet.bench import rtcm as bench


def test_bench_runs_and_reports_every_case(monkeypatch, capsys):
    monkeypatch.setattr(bench, "SECONDS_PER_REPEAT", 0.002)
    monkeypatch.setattr(bench, "REPEATS", 1)
    monkeypatch.setattr(bench, "BATCH_RECEIVERS", 20)
    bench.main(["--json"])
    result = json.loads(capsys.readouterr().out)
    rows = result["results"]
    assert rows["decode"]["ours"] > 0 and rows["decode"]["pyrtcm"] > 0
    assert rows["decode+CRC"]["pyrtcm"] > 0
    assert all(v["ours"] > 0 for v in rows.values())
    assert "12 sat x 2 sig" in result["message"]
    bench.print_table(result)
    table = capsys.readouterr().out
    assert "ratio" in table and "batch encode, 20 rx" in table
