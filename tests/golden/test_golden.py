"""Golden test: today's outputs of the estimators, the VRS streams, the RTCM encoder, the wire primitives and
the centre process, pinned epoch by epoch (tests/golden/data, written by `python -m tests.golden.record`).

A failure names the first epoch and item that differ. Bytes and integers must be equal; positions may
move by 0.5 mm and DD corrections and VRS observations by 0.1 mm (float sums in another order). Code that
moves or renames an API the cases call updates `probes.py`, never the data. When a difference is intended,
say why in the commit and rewrite that case's file with `python -m tests.golden.record CASE`.

    PYTHONPATH=$PWD python -m pytest -q tests/golden                 # every case
    PYTHONPATH=$PWD python -m pytest -q tests/golden -m "not slow"   # without the simulated centre run
    PYTHONPATH=$PWD python -m pytest -q tests/golden -k onboard_static
"""

from __future__ import annotations

import pytest

from tests.conftest import SHARED_DATA
from tests.golden.cases import CASES, GOLDEN_SOURCE, run
from tests.golden.compare import first_difference, load, path_of


def _params():
    for name, (_, needs_shared, slow) in CASES.items():
        marks = ([pytest.mark.shared_data] if needs_shared else []) + ([pytest.mark.slow] if slow else [])
        yield pytest.param(name, marks=marks, id=name)


def _golden(case: str) -> dict:
    source, epochs, items = GOLDEN_SOURCE.get(case, (case, None, None))
    if not path_of(source).exists():
        pytest.fail(f"no golden file {path_of(source)}: run `python -m tests.golden.record {source}`")
    doc = load(source)
    if epochs is not None:
        doc["epochs"] = [{k: v for k, v in rec.items() if k in items} for rec in doc["epochs"][:epochs]]
    return doc


@pytest.mark.parametrize("case", list(_params()))
def test_golden(case):
    _, needs_shared, _ = CASES[case]
    if needs_shared and not SHARED_DATA.is_dir():
        pytest.skip(f"real recordings not available: {SHARED_DATA} is absent")
    recorded = _golden(case)
    now = run(case, SHARED_DATA if needs_shared else None)
    diff = first_difference(case, recorded, now)
    assert diff is None, diff
