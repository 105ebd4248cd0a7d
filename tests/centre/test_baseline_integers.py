"""The baseline's fixed DD integers and their confirmation, as values with their own rules."""

from __future__ import annotations

from augnet.centre.integer_streaks import IntegerStreaks
from augnet.centre.baseline_integers import N1, N2, WIDE_LANE, BaselineIntegers


def test_rereferencing_keeps_every_double_difference():
    f = BaselineIntegers(n1={"G05": 3, "G07": -2, "E11": 4}, n2={"G05": 1, "G07": 6}, wide_lane={"G09": 5})
    f.rereference("G", old="G02", new="G05")  # N(s, G05) = N(s, G02) - N(G05, G02)
    assert f.n1 == {"E11": 4, "G07": -5, "G02": -3}
    assert f.n2 == {"G07": 5, "G02": -1}
    assert f.wide_lane == {}  # no wide lane of the new reference: the system's go
    assert f.both("G07") and not f.both("E11") and f.frequency_count() == 5


def test_forgetting_a_satellite_clears_all_its_tables():
    f = BaselineIntegers(n1={"G05": 3}, n2={"G05": 1}, wide_lane={"G05": 2})
    f.forget("G05")
    assert f.tables() == ({}, {}, {})


def test_an_integer_is_confirmed_after_consecutive_epochs():
    c = IntegerStreaks(epochs=3, epochs_sure=2)
    assert [c.observe("G05", N1, 4, sure=False) for _ in range(3)] == [False, False, True]
    assert not c.observe("G05", N1, 5, sure=False)  # another integer starts again
    c.clear("G05", N1)
    assert [c.observe("G05", N1, 5, sure=True) for _ in range(2)] == [False, True]
    c.observe("G05", N2, 1, sure=True)
    c.observe("E11", WIDE_LANE, 1, sure=True)
    c.forget_system("G")
    assert c.observe("G05", N2, 1, sure=True) is False and c.observe("E11", WIDE_LANE, 1, sure=True) is True
