"""augnet: the one front door (`augnet up`, `augnet sim ...`, `augnet bench ...`, ...).

Each subsystem owns its own typer app in its own module; this file only mounts them, importing each
lazily so a missing optional part never breaks the others.
"""

from __future__ import annotations

import importlib
import sys

import typer

from augnet.blas_threads import limit_blas_threads

app = typer.Typer(help="augnet: track-side GNSS augmentation network.", no_args_is_help=True,
                  add_completion=False)

# (command name, module, attribute, help). A module that does not exist yet is simply not mounted.
SUBAPPS = (
    ("bench", "augnet.bench.cli", "app", "Benchmarks against named peers (prints figures and ratios)."),
    ("caster", "ntrip_caster.cli", "app", "NTRIP caster (v1 and v2)."),
    ("loadtest", "ntrip_caster.loadtest", "app", "NTRIP load generator."),
    ("sim", "stations.cli", "sim_app", "Simulated world: record scenarios."),
    ("stations", "stations.cli", "stations_app", "Stream simulated stations to a caster."),
    ("rssp1", "rssp1.cli", "app", "RSSP-I safety layer tools."),
    ("rtk", "augnet.onboard.cli", "rtk", "Post-process RTK like rnx2rtkp: rover + base RINEX -> solution CSV."),
    ("vrs", "augnet.centre.cli", "vrs", "Write a virtual reference station RINEX file for a point."),
    ("centre", "augnet.centre.cli", "app", "The network engine (control centre)."),
    ("console", "augnet.console.cli", "app", "The operator console."),
    ("scenario", "augnet.scenario.cli", "app", "Run a scenario end to end, faster than real time: report.json + plots."),
    ("track", "augnet.track.cli", "app", "Track topology and track identification (campaign through switches)."),
    ("up", "augnet.system.cli", "up", "The whole system in one process: stations, caster, centre, RSSP-I, trains, console."),
)


_mounted = False


def _mount() -> None:
    """Mount every subsystem's app once (idempotent: tests call it too)."""
    global _mounted
    if _mounted:
        return
    _mounted = True
    for name, module, attr, help_text in SUBAPPS:
        try:
            mod = importlib.import_module(module)
        except ModuleNotFoundError as exc:
            if exc.name and (exc.name == module or module.startswith(exc.name + ".")):
                continue
            raise
        sub = getattr(mod, attr, None)
        if isinstance(sub, typer.Typer):
            app.add_typer(sub, name=name, help=help_text)
        elif callable(sub):  # a single command, e.g. `augnet rtk --rover ...`
            app.command(name=name, help=help_text)(sub)
    # The caster's load generator knows nothing of trains; the system adds its train load to it
    # (`augnet loadtest trains`: many trains with moving GGA on the VRS mountpoint of `augnet up`).
    try:
        from augnet.system.loadtest import trains as train_load
        from ntrip_caster.loadtest import app as loadtest_app
    except ModuleNotFoundError:
        return
    loadtest_app.command(name="trains")(train_load)


@app.command()
def run() -> None:
    """The main job on its embedded defaults (what `make run` starts): `augnet up demo`."""
    from augnet.system.cli import up

    up(scenario="demo", trains=None, duration=None, db="sqlite:///augnet.db", host="127.0.0.1",
       caster_port=2101, console_port=8000, bus="", rbc=True, view=True, report=None,
       state=__import__("pathlib").Path("augnet-up.json"), admin_password="")


def main() -> None:
    limit_blas_threads()  # before the subcommands import numpy: BLAS reads its thread count when it loads
    _mount()
    app()


if __name__ == "__main__":
    sys.exit(main())
