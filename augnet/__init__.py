"""augnet: track-side GNSS augmentation network for satellite-based train control.

Importing augnet changes nothing in the process (no environment variable, no thread pool): the entry points
choose the BLAS threads (`augnet.blas_threads`)."""

__version__ = "0.1.0"
