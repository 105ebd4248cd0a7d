"""Importing augnet and every module of the repository's packages changes nothing in the process: no
environment variable, no BLAS thread pool. The entry points choose the BLAS threads (`augnet.blas_threads`)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

from tests.conftest import REPO_ROOT

PACKAGES = ("augnet", "stations", "ntrip_caster", "rssp1")

IMPORT_EVERYTHING = """
import importlib, json, os, pkgutil
import numpy  # first, as a script would: its BLAS pool is loaded with the library's own thread count
from threadpoolctl import threadpool_info  # sets KMP_DUPLICATE_LIB_OK itself (a dependency, not augnet)
before = dict(os.environ)
blas_before = sorted((i["filepath"], i["num_threads"]) for i in threadpool_info() if i["user_api"] == "blas")
names = []
for package in {packages!r}:
    names.append(package)
    pkg = importlib.import_module(package)
    names += [m.name for m in pkgutil.walk_packages(pkg.__path__, package + ".")
              if not m.name.endswith(".__main__")]  # `python -m` entry points run their command on import
for name in names:
    importlib.import_module(name)
blas_after = sorted((i["filepath"], i["num_threads"]) for i in threadpool_info() if i["user_api"] == "blas")
print(json.dumps({{"modules": len(names), "blas_changed": blas_before != blas_after,
                   "changed": {{k: v for k, v in os.environ.items() if before.get(k) != v}},
                   "removed": sorted(set(before) - set(os.environ))}}))
"""


def _clean_env(**extra: str) -> dict[str, str]:
    """The environment of a shell without any BLAS setting, the repository on the path."""
    env = {k: v for k, v in os.environ.items() if k in ("PATH", "HOME", "LANG", "TMPDIR")}
    return {**env, "PYTHONPATH": str(REPO_ROOT), **extra}


def _run(code: str, **extra: str) -> dict:
    out = subprocess.run([sys.executable, "-c", code], env=_clean_env(**extra), cwd=REPO_ROOT,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_importing_every_module_leaves_the_environment_and_blas_alone():
    result = _run(IMPORT_EVERYTHING.format(packages=PACKAGES))
    assert result["modules"] > 100
    assert result["changed"] == {} and result["removed"] == []
    assert not result["blas_changed"]


LIMIT_THEN_NUMPY = """
import json, os
from augnet.blas_threads import BLAS_THREAD_VARIABLES, limit_blas_threads
limit_blas_threads()
import numpy
from threadpoolctl import threadpool_info
print(json.dumps({"env": {v: os.environ.get(v) for v in BLAS_THREAD_VARIABLES},
                  "blas_threads": sorted({i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"})}))
"""


def test_an_entry_point_gets_one_blas_thread_for_itself_and_its_children():
    result = _run(LIMIT_THEN_NUMPY)
    assert result["env"] == {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    assert result["blas_threads"] == [1]


def test_a_thread_count_the_user_set_wins():
    result = _run(LIMIT_THEN_NUMPY, OPENBLAS_NUM_THREADS="2")
    assert result["env"]["OPENBLAS_NUM_THREADS"] == "2"
    assert result["blas_threads"] == [2]


NUMPY_THEN_LIMIT = """
import json
import numpy
from threadpoolctl import threadpool_info
from augnet.blas_threads import limit_blas_threads
limit_blas_threads()  # numpy came first: the running pool is limited
print(json.dumps({"blas_threads": sorted({i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"})}))
"""


def test_after_numpy_the_running_blas_pool_is_limited():
    assert _run(NUMPY_THEN_LIMIT)["blas_threads"] == [1]
