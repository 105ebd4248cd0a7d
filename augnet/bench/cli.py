"""`augnet bench NAME [ARGS]`: one module per benchmark in this package, each with a `main(argv)` that
measures ours and the named peer side by side in one run and prints figures and ratios."""

from __future__ import annotations

import contextlib
import importlib
import inspect
import io
import json

import typer

from augnet.bench import yardstick

BENCHMARKS = {
    "rtcm": ("augnet.bench.rtcm", "RTCM 3 codec: decode/encode against pyrtcm, batch MSM7 encoder."),
    "wire": ("augnet.bench.wire", "augwire: CRC-24Q against pyrtcm by length, RTCM framer, chunked decoder."),
    "sim": ("augnet.bench.sim", "Simulated world: epochs per second for `demo` against the 50x real-time goal."),
    "rssp1": ("augnet.bench.rssp1", "RSSP-I: frames encoded + verified per second."),
    "caster": ("augnet.bench.caster", "NTRIP caster under load (see also `augnet loadtest`)."),
    "rtk": ("augnet.bench.rtk", "Onboard RTK: time per epoch against RTKLIB rnx2rtkp."),
    "centre": ("augnet.bench.centre", "Network solution per epoch at 6/20/60 stations (rnx2rtkp yardstick, --against TREE) and VRS synthesis + encoding for many trains."),
    "protocol": ("augnet.bench.protocol", "Centre-process protocol: encode/decode per epoch against pickle."),
    "up": ("augnet.bench.up", "The whole system: console p99 and 2,000 trains' correction age while augnet up demo runs."),
}
# `augnet bench all` runs these: the ones that finish in a minute.
QUICK = ("rtcm", "rssp1", "sim")

app = typer.Typer(no_args_is_help=True, help="Benchmarks against named peers.")


# These measure the yardstick themselves (before/after the run, in their own JSON and table).
OWN_YARDSTICK = ("centre", "rtcm")


def _call(module, argv: list[str]) -> None:
    if inspect.signature(module.main).parameters:
        module.main(argv)
    else:
        module.main()


def _run(name: str, argv: list[str] | None = None) -> None:
    """Run one benchmark with the machine yardstick of the same run (issue 17): added to its JSON, printed
    after its table."""
    argv = list(argv or [])
    module = importlib.import_module(BENCHMARKS[name][0])
    if name in OWN_YARDSTICK:
        _call(module, argv)
        return
    yard = yardstick.yardstick_ms()
    if "--json" not in argv and name != "caster":  # caster always prints JSON
        _call(module, argv)
        print(yardstick.describe(yard), flush=True)
        return
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        _call(module, argv)
    text = buf.getvalue()
    try:
        result = json.loads(text)
    except ValueError:  # not one JSON document: keep it as printed, state the yardstick after it
        print(text, end="")
        print(yardstick.describe(yard), flush=True)
        return
    if isinstance(result, dict):
        result = yardstick.annotate(result, yard)
    else:
        result = {"results": result, yardstick.YARDSTICK_KEY: None if yard is None else round(yard, 3)}
    print(json.dumps(result, indent=2), flush=True)


def run_all() -> None:
    for name in QUICK:
        try:
            importlib.import_module(BENCHMARKS[name][0])
        except ModuleNotFoundError:
            continue
        print(f"== augnet bench {name} ==", flush=True)
        _run(name)


@app.command("all")
def all_() -> None:
    """Run the quick benchmarks one after another."""
    run_all()


def _make_command(name: str, help_text: str):
    def command(ctx: typer.Context) -> None:
        _run(name, list(ctx.args))

    command.__doc__ = help_text
    return command


for _name, (_module, _help) in BENCHMARKS.items():
    app.command(_name, help=_help, context_settings={"allow_extra_args": True,
                                                        "ignore_unknown_options": True})(_make_command(_name, _help))
