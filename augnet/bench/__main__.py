"""`python -m augnet.bench rtcm` is `augnet bench rtcm`."""

from augnet.blas_threads import limit_blas_threads

limit_blas_threads()  # as `augnet bench` does, before the benchmarks import numpy

from augnet.bench.cli import app  # noqa: E402 - after the BLAS threads are set

app()
