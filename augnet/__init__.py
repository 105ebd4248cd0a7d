"""augnet: track-side GNSS augmentation network for satellite-based train control."""

import os
import sys

# The numerics here work on small matrices (tens to a few hundred rows) many times per epoch; BLAS worker
# threads only add contention there (a 100x100 Kalman update measured 0.8 ms with one thread and 3-70 ms
# with two on a loaded 2-core machine). Set before numpy is imported; an explicit setting by the user wins.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
if "numpy" in sys.modules and os.environ.get("OPENBLAS_NUM_THREADS") == "1":
    # numpy came first (a script that imported it before us): limit the running BLAS pool instead.
    try:
        from threadpoolctl import threadpool_limits

        threadpool_limits(limits=1, user_api="blas")
    except ImportError:  # pragma: no cover - threadpoolctl is a dependency
        pass

__version__ = "0.1.0"
