"""augnet: track-side GNSS augmentation network for satellite-based train control."""

import os

# The numerics here work on small matrices (tens to a few hundred rows) many times per epoch; BLAS worker
# threads only add contention there (a 100x100 solve measured 40x slower with threads on a loaded 2-core
# machine). Set before numpy is imported; an explicit setting by the user wins.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

__version__ = "0.1.0"
