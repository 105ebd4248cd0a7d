"""The state-vector index allocator both estimators use."""
import numpy as np
import pytest

from augnet.gnss.state_layout import StateLayout


def test_blocks_keep_their_values_and_are_uncorrelated_at_birth():
    s = StateLayout(np.zeros(2), np.eye(2))
    i = s.add("G01", [1.0, 2.0], [4.0, 9.0])
    assert i == 2 and s.x.tolist() == [0, 0, 1, 2]
    assert np.array_equal(s.P[2:, 2:], np.diag([4.0, 9.0])) and not s.P[:2, 2:].any()
    with pytest.raises(KeyError):
        s.add("G01", [0.0, 0.0], [1.0, 1.0])


def test_reuse_freed_hands_the_last_released_slot_to_the_next_block():
    s = StateLayout(np.zeros(3), np.eye(3), reuse_freed=True)
    a, b, c = (s.add(k, [1.0], [1.0]) for k in "abc")
    s.P[a, b] = s.P[b, a] = 0.5
    s.remove(["a", "b"])
    assert s.x.size == 6 and s.P[a, b] == 0.0 and s.index("c") == c
    assert s.add("d", [7.0], [2.0]) == b and s.add("e", [8.0], [3.0]) == a
    assert s.add("f", [9.0], [4.0]) == 6


def test_compacting_removal_keeps_order_and_correlations_of_the_rest():
    s = StateLayout(np.zeros(2), np.eye(2), reuse_freed=False)
    for k, v in zip("abc", (1.0, 2.0, 3.0)):
        s.add(k, [v, -v], [1.0, 1.0])
    s.P[s.index("a"), s.index("c")] = s.P[s.index("c"), s.index("a")] = 0.25
    s.remove(["b", "zz"])
    assert s.x.tolist() == [0, 0, 1, -1, 3, -3]
    assert s.index("a") == 2 and s.index("c") == 4 and s.P[2, 4] == 0.25
    assert s.indices(["c", "a"]).tolist() == [4, 2] and "b" not in s and len(s) == 2
