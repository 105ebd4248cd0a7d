"""Batch MSM encoder: byte for byte what the single-message path gives, and pyrtcm reads it."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from augnet.gnss.rtcm import EncodeError, Observables, encode_msm, encode_msm_batch, frame, observables_to_msm
from augwire.crc24q import crc24q, crc24q_bytewise, crc24q_rows

from ._support import assert_same_fields, pyrtcm_fields
from .test_observables import random_observables


def batch_inputs(rng, system, nrx, nsat, nsig, missing):
    base = random_observables(rng, system, nsat, nsig, missing=0.0)
    shape = (nrx, nsat, nsig)
    pr = base.pseudorange_m + rng.normal(0, 20, shape)  # trains a few km apart see shifted ranges
    cp = base.phase_cycles + rng.normal(0, 50, shape)
    dop = base.doppler_hz + rng.normal(0, 0.3, (nrx, nsat, 1))
    cnr = base.cnr_dbhz + rng.normal(0, 2, shape)
    lock = rng.uniform(0, 1e6, shape)
    half = rng.random(shape) < 0.1
    gone = rng.random(shape) < missing  # each receiver loses different cells: several layouts
    gone_sat = rng.random((nrx, nsat, 1)) < missing / 2
    for a in (pr, cp):
        a[gone | gone_sat] = np.nan
    dop[gone] = np.nan
    station_ids = rng.integers(0, 4096, nrx)
    epochs = rng.integers(0, 604_800_000, nrx)
    return base.sat_ids, base.sig_ids, station_ids, epochs, pr, cp, dop, cnr, lock, half


def single(system, level, sat_ids, sig_ids, station_ids, epochs, pr, cp, dop, cnr, lock, half, i, **header):
    obs = Observables(system, sat_ids, sig_ids, pr[i], cp[i], dop[i], cnr[i], lock[i], half[i])
    return frame(encode_msm(observables_to_msm(obs, level, int(station_ids[i]), int(epochs[i]), **header)))


@pytest.mark.parametrize("system", ["G", "E", "C"])
@pytest.mark.parametrize("level", [4, 7])
@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), nrx=st.integers(1, 40), nsat=st.integers(1, 21),
       nsig=st.integers(1, 3), missing=st.sampled_from([0.0, 0.05, 0.3]))
def test_batch_equals_single_messages(system, level, seed, nrx, nsat, nsig, missing):
    rng = np.random.default_rng(seed)
    nsat = min(nsat, 64 // nsig)
    args = batch_inputs(rng, system, nrx, nsat, nsig, missing)
    batch = encode_msm_batch(system, level, *args, iods=3, clock_steering=1)
    assert len(batch) == nrx
    for i in range(nrx):
        assert batch[i] == single(system, level, *args, i, iods=3, clock_steering=1), f"receiver {i}"
    assert b"".join(batch.frames()) == batch.data


@pytest.mark.parametrize("level", [4, 7])
def test_pyrtcm_reads_batch_output(level):
    rng = np.random.default_rng(11)
    args = batch_inputs(rng, "G", 25, 12, 2, 0.05)
    batch = encode_msm_batch("G", level, *args)
    station_ids, epochs = args[2], args[3]
    for i in range(len(batch)):
        theirs = pyrtcm_fields(batch[i])
        assert theirs["DF003"] == station_ids[i] and theirs["DF004"] == epochs[i]
        obs_frame = single("G", level, *args, i)
        assert_same_fields(pyrtcm_fields(obs_frame), theirs)


def test_thousand_receivers_one_layout():
    rng = np.random.default_rng(12)
    args = batch_inputs(rng, "G", 1000, 12, 2, 0.0)
    batch = encode_msm_batch("G", 7, *args)
    assert len(batch) == 1000 and len(set(np.diff(batch.offsets))) == 1
    for i in (0, 499, 511, 512, 999):
        assert batch[i] == single("G", 7, *args, i)
        assert crc24q(batch[i]) == 0


def test_batch_rejects_more_than_64_cells():
    rng = np.random.default_rng(13)
    args = batch_inputs(rng, "C", 2, 22, 3, 0.0)
    with pytest.raises(EncodeError, match="64"):
        encode_msm_batch("C", 7, *args)


def test_empty_batch():
    pr = np.zeros((0, 3, 2))
    batch = encode_msm_batch("G", 7, [1, 2, 3], [2, 16], [], [], pr, pr)
    assert len(batch) == 0 and batch.data == b""


@settings(max_examples=50, deadline=None)
@given(st.integers(0, 60).flatmap(lambda n: st.lists(st.binary(min_size=n, max_size=n), min_size=1, max_size=8)))
def test_vectorised_crc_equals_table_crc(rows):
    arr = np.array([list(r) for r in rows], dtype=np.uint8).reshape(len(rows), len(rows[0]))
    assert crc24q_rows(arr).tolist() == [crc24q_bytewise(r) for r in rows]


@settings(max_examples=50, deadline=None)
@given(st.binary(max_size=1029))
def test_crc24q_numpy_path_equals_byte_loop(data):
    assert crc24q(data) == crc24q_bytewise(data)


def test_blocks_join_seamlessly(monkeypatch):
    # Receivers are encoded in cache-sized blocks; block edges must not show in the output.
    import augnet.gnss.rtcm.batch as batch_mod

    monkeypatch.setattr(batch_mod, "RECEIVERS_PER_BLOCK", 7)
    rng = np.random.default_rng(14)
    args = batch_inputs(rng, "E", 40, 9, 3, 0.1)
    batch = encode_msm_batch("E", 7, *args, multiple=1)
    assert len(batch) == 40
    for i in range(40):
        assert batch[i] == single("E", 7, *args, i, multiple=1), f"receiver {i}"


@pytest.mark.parametrize("msg_type", [1005, 1006, 1019, 1042, 1045, 1046])
@settings(max_examples=5, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data(), nrx=st.integers(1, 30))
def test_fixed_batch_equals_single_messages(msg_type, data, nrx):
    from augnet.gnss.rtcm import RtcmMessage, encode_fixed_batch, encode_frame

    from ._support import fixed_message_fields

    per_rx = [data.draw(fixed_message_fields(msg_type)) for _ in range(nrx)]
    columns = {k: np.array([f[k] for f in per_rx]) for k in per_rx[0] if k != "DF002"}
    batch = encode_fixed_batch(msg_type, columns)
    assert len(batch) == nrx
    for i, f in enumerate(per_rx):
        assert batch[i] == encode_frame(RtcmMessage(msg_type, f))


def test_fixed_batch_vrs_positions_read_by_pyrtcm():
    from augnet.gnss.rtcm import encode_fixed_batch

    rng = np.random.default_rng(15)
    n = 50
    xyz = np.array([-2_148_744.0, 4_426_641.0, 4_044_655.0]) + rng.uniform(-5e4, 5e4, (n, 3))
    fields = {"DF003": np.arange(n), "DF021": 0, "DF022": 1, "DF023": 0, "DF024": 1, "DF141": 1, "DF142": 0,
              "DF364": 0, "DF025": xyz[:, 0], "DF026": xyz[:, 1], "DF027": xyz[:, 2], "DF028": 0.0}
    batch = encode_fixed_batch(1006, fields)
    for i in range(n):
        theirs = pyrtcm_fields(batch[i])
        assert theirs["DF003"] == i and theirs["DF141"] == 1
        assert abs(theirs["DF025"] - xyz[i, 0]) <= 5e-5 and abs(theirs["DF027"] - xyz[i, 2]) <= 5e-5
    with pytest.raises(EncodeError, match="DF025"):
        encode_fixed_batch(1006, fields | {"DF025": 2e7})  # beyond the 38-bit, 0.1 mm field
    del fields["DF026"]
    with pytest.raises(EncodeError, match="DF026"):
        encode_fixed_batch(1006, fields)
    with pytest.raises(EncodeError, match="variable-length"):
        encode_fixed_batch(1033, {"DF003": 1})
