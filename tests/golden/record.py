"""Write the golden files: `python -m tests.golden.record [case ...]` (all cases when none is named).
`--json DIR CASE...` writes the cases' outputs to DIR/CASE.json instead (how test_golden runs a case at the AVX2 level).

Only on purpose: the golden files pin today's outputs, and rewriting them accepts whatever the code now
computes. Cases that read ../shared/data are left out (and say so) when it is absent.
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
import time

from tests.conftest import SHARED_DATA
from tests.golden.cases import CASES, GOLDEN_SOURCE, run
from tests.golden.compare import DATA_DIR, dumps, path_of
from tests.golden.simd import needs_pinning, pinned_env


def main(argv: list[str]) -> int:
    if needs_pinning():  # numpy at the AVX2 level, as the golden files were written (simd.py)
        os.execve(sys.executable, [sys.executable, "-m", "tests.golden.record", *argv], pinned_env())
    if argv[:1] == ["--json"]:
        if len(argv) < 3 or any(c not in CASES for c in argv[2:]):
            print(f"usage: --json DIR CASE...; cases: {', '.join(CASES)}", file=sys.stderr)
            return 2
        for case in argv[2:]:
            shared = SHARED_DATA if CASES[case][1] else None
            with open(os.path.join(argv[1], f"{case}.json"), "w", encoding="utf-8") as f:
                json.dump(run(case, shared), f)
        return 0
    names = argv or list(CASES)
    unknown = [n for n in names if n not in CASES]
    if unknown:
        print(f"unknown case(s) {', '.join(unknown)}; cases: {', '.join(CASES)}", file=sys.stderr)
        return 2
    DATA_DIR.mkdir(exist_ok=True)
    shared = SHARED_DATA if SHARED_DATA.is_dir() else None
    for name in names:
        _, needs_shared, _ = CASES[name]
        if name in GOLDEN_SOURCE:
            print(f"{name}: nothing to write (compared with {GOLDEN_SOURCE[name][0]}'s file)")
            continue
        if needs_shared and shared is None:
            print(f"{name}: skipped, {SHARED_DATA} is absent")
            continue
        c0 = time.process_time()
        data = dumps(name, run(name, shared if needs_shared else None))
        path = path_of(name)
        old = path.read_bytes() if path.exists() else None
        path.write_bytes(data)
        what = "unchanged" if old == data else ("new" if old is None else "CHANGED")
        print(f"{name}: wrote {path} ({len(data)} bytes, sha256 {hashlib.sha256(data).hexdigest()[:16]}, "
              f"{what}; {time.process_time() - c0:.1f} s CPU)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
