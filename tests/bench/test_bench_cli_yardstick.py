"""Every `augnet bench` run carries the yardstick of the same run (issue 17), via augnet.bench.cli._run."""

import json
import sys
import types

import pytest

from augnet.bench import cli, yardstick


@pytest.fixture
def fake_bench(monkeypatch):
    mod = types.ModuleType("fake_bench_h17")

    def main(argv):
        print(json.dumps({"x_ms_per_epoch": 12.0}) if "--json" in argv else "table")

    mod.main = main
    monkeypatch.setitem(sys.modules, mod.__name__, mod)
    monkeypatch.setitem(cli.BENCHMARKS, "fake", (mod.__name__, "fake"))
    monkeypatch.setattr(yardstick, "yardstick_ms", lambda: 4.0)  # rnx2rtkp is timed in test_bench_centre


def test_json_bench_gets_the_yardstick_and_units(fake_bench, capsys):
    cli._run("fake", ["--json"])
    out = json.loads(capsys.readouterr().out)
    assert out[yardstick.YARDSTICK_KEY] == 4.0 and out["x_yardsticks"] == 3.0


def test_table_bench_prints_the_yardstick(fake_bench, capsys):
    cli._run("fake", [])
    assert "yardstick: RTKLIB rnx2rtkp 4.000 ms" in capsys.readouterr().out


def test_every_listed_bench_is_covered():
    assert set(cli.OWN_YARDSTICK) <= set(cli.BENCHMARKS)
