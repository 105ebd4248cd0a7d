"""FixConfirmation: a streak of agreeing integer decisions, with states that come, go and restart."""

from __future__ import annotations

import numpy as np

from augnet.gnss.fix_confirmation import FixConfirmation, IntegerDecision

# five SD ambiguity states (indices 3..7 behind three position states), fixed DDs against state 3
I = np.array([4, 5, 6, 7])
IREF = np.array([3, 3, 3, 3])


def _fixed_state(values, sigma=1e-3):
    x = np.zeros(8)
    x[3:] = values
    P = np.eye(8) * sigma**2
    return x, P


def _decision(x, P, names):
    Hc = np.zeros((4, 8))
    Hc[np.arange(4), I] = 1.0
    Hc[np.arange(4), IREF] = -1.0
    return IntegerDecision.from_fix(lambda i: names[i], I, IREF, Hc, np.round(Hc @ x), x, P)


NAMES = {i: (f"G{i:02d}", 0, 1) for i in range(3, 8)}  # (satellite, slot, arc serial)


def _index_of(names):
    where = {v: k for k, v in names.items()}
    return lambda ident: where.get(ident, -1)


def test_the_same_integers_make_a_streak_and_a_change_breaks_it():
    c = FixConfirmation(min_count=4)
    x, P = _fixed_state([0, 3, 5, -2, 8])
    assert c.observe(_decision(x, P, NAMES), _index_of(NAMES), x, P) == 1
    assert c.observe(_decision(x, P, NAMES), _index_of(NAMES), x, P) == 2
    x2, _ = _fixed_state([0, 3, 5, -2, 9])  # one DD ambiguity one cycle off
    assert c.observe(_decision(x2, P, NAMES), _index_of(NAMES), x2, P) == 1
    c.reset()
    assert c.decision is None and c.count == 0


def test_a_restarted_state_is_left_out_of_the_comparison():
    c = FixConfirmation(min_count=3)
    x, P = _fixed_state([0, 3, 5, -2, 8])
    c.observe(_decision(x, P, NAMES), _index_of(NAMES), x, P)
    # state 7 slipped: a new arc (serial 2) with a different integer; the other three DDs still agree
    renamed = dict(NAMES)
    renamed[7] = ("G07", 0, 2)
    x2, _ = _fixed_state([0, 3, 5, -2, 11])
    assert c.observe(_decision(x2, P, renamed), _index_of(renamed), x2, P) == 2


def test_too_few_comparable_functionals_do_not_agree():
    # 4 determined DDs and 4 fixed combinations: a restarted state leaves 3 + 3 comparable, fewer than 7
    c = FixConfirmation(min_count=7)
    x, P = _fixed_state([0, 3, 5, -2, 8])
    c.observe(_decision(x, P, NAMES), _index_of(NAMES), x, P)
    renamed = dict(NAMES)
    renamed[7] = ("G07", 0, 2)
    assert c.observe(_decision(x, P, renamed), _index_of(renamed), x, P) == 1


def test_undetermined_functionals_do_not_count():
    c = FixConfirmation(min_count=4)
    x, P = _fixed_state([0, 3, 5, -2, 8])
    c.observe(_decision(x, P, NAMES), _index_of(NAMES), x, P)
    _, loose = _fixed_state([0, 3, 5, -2, 8], sigma=0.5)  # the same values, but nothing determined
    assert c.observe(_decision(x, P, NAMES), _index_of(NAMES), x, loose) == 1


def test_a_determined_ambiguity_outside_the_fixed_combinations_is_part_of_the_decision():
    # the fix constrains G04..G06 only; G07's DD is determined already (held): the decision covers it too
    x, P = _fixed_state([0, 3, 5, -2, 8])
    Hc = np.zeros((3, 8))
    Hc[np.arange(3), I[:3]] = 1.0
    Hc[np.arange(3), IREF[:3]] = -1.0
    d = IntegerDecision.from_fix(lambda i: NAMES[i], I, IREF, Hc, np.round(Hc @ x), x, P)
    assert set(d.states) == set(NAMES.values())
    assert d.agrees(_index_of(NAMES), x, P, min_count=4)
    x2, _ = _fixed_state([0, 3, 5, -2, 9])
    assert not d.agrees(_index_of(NAMES), x2, P, min_count=4)
