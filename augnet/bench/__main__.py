"""`python -m augnet.bench rtcm` is `augnet bench rtcm`."""

from augnet.bench.cli import app

app()
