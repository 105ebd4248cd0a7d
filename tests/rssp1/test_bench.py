"""The RSSP-I benchmark runs end to end (tiny counts here; the figures come from `augnet bench rssp1`)."""

from __future__ import annotations

import json

from augnet.bench import rssp1 as bench


def test_bench_runs_and_reports_every_path(monkeypatch, capsys):
    monkeypatch.setattr(bench, "FRAMES", 200)
    monkeypatch.setattr(bench, "TRIALS", 1)
    bench.main(["--json"])
    result = json.loads(capsys.readouterr().out)
    assert set(result["results"]) == {"16", "96"}
    for rows in result["results"].values():
        assert set(rows) == {"codec", "endpoint", "sealed", "C CRCs (peer)"}
        assert all(r["wall"] > 0 and r["cpu"] > 0 for r in rows.values())
    bench.print_table(result)
    assert "goal 100,000" in capsys.readouterr().out
