"""`augnet vrs` refuses a station the others single out, and only then (decision 0163)."""

from __future__ import annotations

import pytest

from augnet.centre.postprocess import PostprocessError, _judge_stations
from augnet.centre.station_check import CheckResult


class _Check:
    def __init__(self, names, flagged):
        self.names = names
        self._res = CheckResult(rows=5000, span_s=10800.0, flagged=flagged, verdict=True)

    def result(self):
        return self._res


def test_one_station_singled_out_stops_the_run_naming_it():
    with pytest.raises(PostprocessError, match="GARR.*--coords"):
        _judge_stations(_Check(["CREU", "EBRE", "GARR"], ["GARR"]))


@pytest.mark.parametrize("flagged", [["CREU", "EBRE"], ["CREU", "EBRE", "GARR"]])
def test_no_culprit_when_half_or_more_are_flagged(flagged):
    res = _judge_stations(_Check(["CREU", "EBRE", "GARR"], flagged))
    assert res.flagged == flagged
    assert "unconfirmed" in res.lines()[-1]


def test_nothing_flagged_passes():
    assert _judge_stations(_Check(["CREU", "EBRE", "GARR"], [])).flagged == []
