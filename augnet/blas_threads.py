"""One BLAS thread per augnet process, set explicitly at each process's entry point.

augnet's numerics work on small matrices (tens to a few hundred rows) many times per epoch: BLAS worker
threads only add contention there, the more so on a machine whose cores are busy with the event loop and the
centre process (docs/decisions/0070-blas-threads-at-entry-points.md). Importing augnet sets nothing; the
entry points call `limit_blas_threads()`: `augnet` (cli.main), `python -m augnet.bench`, each benchmark run as
a script, the centre process, the test suite.
"""

from __future__ import annotations

import os
import sys

BLAS_THREADS = 1
# OpenBLAS, OpenMP (OpenBLAS built with it, MKL's default) and MKL each read their own variable when loaded.
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def limit_blas_threads() -> None:
    """One BLAS thread for this process and the processes it starts; a variable already set wins (the user's,
    or the one a spawned process inherited).

    BLAS libraries read the variables when numpy loads them, so call this before numpy is imported. When numpy
    was loaded before any setting, its running BLAS thread pool is limited instead (threadpoolctl)."""
    preset = os.environ.get("OPENBLAS_NUM_THREADS")  # numpy's wheels carry OpenBLAS
    for var in BLAS_THREAD_VARIABLES:
        os.environ.setdefault(var, str(BLAS_THREADS))
    if "numpy" in sys.modules and preset is None:
        from threadpoolctl import threadpool_limits

        threadpool_limits(limits=BLAS_THREADS, user_api="blas")
