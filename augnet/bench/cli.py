"""`augnet bench NAME`: one module per benchmark in this package, each with a `main()` that prints."""

from __future__ import annotations

import importlib

import typer

app = typer.Typer(no_args_is_help=True)

BENCHMARKS = {
    "rtcm": "augnet.bench.rtcm",
}


def _run(name: str) -> None:
    importlib.import_module(BENCHMARKS[name]).main()


def run_all() -> None:
    for name in BENCHMARKS:
        _run(name)


@app.command()
def all() -> None:  # noqa: A001 - the command is called `all`
    """Run every benchmark."""
    run_all()


@app.command()
def rtcm() -> None:
    """RTCM 3 codec: our decoder/encoder against pyrtcm, and the batch MSM7 encoder."""
    _run("rtcm")
