"""The RSSP-I benchmark runs end to end (tiny counts here; the figures come from `augnet bench rssp1`)."""

from __future__ import annotations

import json

import pytest

from augnet.bench import rssp1 as bench

pytestmark = pytest.mark.slow


def test_bench_runs_and_reports_every_path(monkeypatch, capsys):
    monkeypatch.setattr(bench, "FRAMES", 200)
    monkeypatch.setattr(bench, "TRIALS", 1)
    monkeypatch.setattr(bench, "BATCH", 64)
    bench.main(["--json"])
    result = json.loads(capsys.readouterr().out)
    assert set(result["results"]) == {"16", "96"}
    for rows in result["results"].values():
        assert set(rows) == set(bench.PATHS) >= {"codec", "codec (pure Python)", "batch", "C CRCs (peer)"}
        assert all(r["wall"] > 0 and r["cpu"] > 0 for r in rows.values())
    assert isinstance(result["goal_holds"], bool) and result["crc_backend"] in ("numba", "python")
    bench.print_table(result)
    out = capsys.readouterr().out
    assert "goal 100,000" in out and "peer: per-frame codec, pure Python" in out
    assert ("does NOT hold" in out) != result["goal_holds"]


def test_batch_path_counts_partial_batches(monkeypatch):
    monkeypatch.setattr(bench, "BATCH", 7)
    bench.batch_run(16)(30)  # raises if any frame failed to verify
