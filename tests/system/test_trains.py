"""The onboard trains inside `augnet up` share the loop with the caster: while it writes an epoch's VRS to
every client they hold their processing, and catch up when told it is written."""

from __future__ import annotations

from augnet.system.trains import MAX_BASE_WAIT_S, OnboardTrain


class _Epoch:
    def __init__(self, t: float):
        self.time = t


def test_a_train_holds_its_epochs_while_the_caster_delivers_and_then_processes_them_in_order():
    held = [True]
    tr = OnboardTrain("T1", lambda: None, None, "127.0.0.1", 1, "VRS", hold=lambda: held[0])
    done = []
    tr._process = lambda ep, arrived: done.append(ep.time)
    now = 1_479_350_010.0
    for t in (now - 2.0, now - 1.0):  # both rover epochs have their VRS epoch
        tr.rover_queue.append((_Epoch(t), t + 0.05))
        tr.bases[round(t, 3)] = _Epoch(t)
    tr._drain(now)
    assert done == [] and len(tr.rover_queue) == 2  # held, even the one waiting longer than MAX_BASE_WAIT_S
    assert now - (now - 2.0 + 0.05) > MAX_BASE_WAIT_S
    held[0] = False
    tr.resume()
    assert done == [now - 2.0, now - 1.0] and not tr.rover_queue
    # without a hold (a train alone) it processes as soon as the pair is there
    free = OnboardTrain("T2", lambda: None, None, "127.0.0.1", 1, "VRS")
    free._process = lambda ep, arrived: done.append(("T2", ep.time))
    free.rover_queue.append((_Epoch(now), now))
    free.bases[round(now, 3)] = _Epoch(now)
    free._drain(now)
    assert done[-1] == ("T2", now)


def test_while_bounds_come_a_rover_epoch_waits_for_its_vrs_epochs_4001_too():
    import numpy as np

    from augnet.gnss.rtcm.correction_bound import CorrectionBoundMessage
    from augnet.onboard.correction_bound import epoch_key

    tr = OnboardTrain("T3", lambda: None, None, "127.0.0.1", 1, "VRS")
    done = []
    tr._process = lambda ep, arrived: done.append(ep.time)
    now = 1_479_350_010.0
    tr.base_dec.bounds.add(CorrectionBoundMessage(1, epoch_key(now - 1.0), 1, ["G01"], np.array([0.01])))
    tr.rover_queue.append((_Epoch(now), now))
    tr.bases[round(now, 3)] = _Epoch(now)  # the VRS epoch came, its 4001 (after the MSM) not yet
    tr._drain(now + 0.1)
    assert done == []
    tr.base_dec.bounds.add(CorrectionBoundMessage(1, epoch_key(now), 1, ["G01"], np.array([0.01])))
    tr._drain(now + 0.2)
    assert done == [now]
    tr.rover_queue.append((_Epoch(now + 1.0), now + 1.0))  # a 4001 that never comes: MAX_BASE_WAIT_S, then on
    tr.bases[round(now + 1.0, 3)] = _Epoch(now + 1.0)
    tr._drain(now + 1.0 + MAX_BASE_WAIT_S)
    assert done == [now, now + 1.0]
