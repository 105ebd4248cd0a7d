"""The shared bench yardstick (issue 17): annotate states it in JSON and converts figures to its units."""

from augnet.bench import centre, yardstick


def test_annotate_converts_per_epoch_figures_to_yardstick_units():
    r = yardstick.annotate({"net_60_ms_per_epoch": 30.0, "edges": 5}, 2.0)
    assert r[yardstick.YARDSTICK_KEY] == 2.0
    assert r["net_60_yardsticks"] == 15.0
    assert "edges_yardsticks" not in r


def test_absent_yardstick_is_stated_not_dropped():
    r = yardstick.annotate({"net_60_ms_per_epoch": 30.0}, None)
    assert yardstick.YARDSTICK_KEY in r and r[yardstick.YARDSTICK_KEY] is None
    assert "no yardstick" in yardstick.describe(None)


def test_centre_uses_the_shared_yardstick():
    assert centre.yardstick_ms is yardstick.yardstick_ms
