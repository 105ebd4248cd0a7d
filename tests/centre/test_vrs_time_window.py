"""`augnet vrs --start/--end`: a span of the day, parsed strictly, the network starting cold at its first epoch."""

from __future__ import annotations

import numpy as np
import pytest

from augnet.centre.postprocess import PostprocessError, parse_time_of_day, window_epochs

DAY0 = 1_268_870_400.0 - 1_268_870_400.0 % 86400.0  # some GPS day's start


@pytest.mark.parametrize("text, seconds", [("00:00", 0.0), ("03:20", 12000.0), ("5:59:59", 21599.0),
                                           ("23:59:30.5", 86370.5), ("24:00", 86400.0)])
def test_times_of_day_parse(text, seconds):
    assert parse_time_of_day(text, "--start") == seconds


@pytest.mark.parametrize("text", ["", "3", "03-20", "25:00", "12:60", "12:00:60", "24:00:01", "noon"])
def test_bad_times_are_refused_naming_the_option(text):
    with pytest.raises(PostprocessError, match="--end"):
        parse_time_of_day(text, "--end")


def test_the_window_keeps_its_ends_and_counts_from_the_first_epochs_day():
    t = DAY0 + np.arange(0.0, 7200.0 + 1, 30.0)
    keep = window_epochs(t, 1800.0, 3600.0)
    assert t[keep][0] == DAY0 + 1800.0 and t[keep][-1] == DAY0 + 3600.0 and keep.sum() == 61
    assert window_epochs(t, None, None).all()
    assert not window_epochs(t, 7300.0, None).any()
