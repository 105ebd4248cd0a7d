"""Command line of the control centre: `augnet vrs` (post-processed virtual RINEX) and `augnet centre ...`."""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

PROGRESS_STEP = 0.1  # share of the epochs between progress lines

app = typer.Typer(no_args_is_help=True, help="The network engine (control centre).")


def vrs(
    record: Path = typer.Option(..., "--record",
                                help="folder of reference-station RINEX files or a `sim record` output"),
    at: str = typer.Option(..., "--at",
                           help="the VRS point: LAT,LON,H (degrees, degrees, ellipsoidal m) or X,Y,Z (ECEF m)"),
    out: Path = typer.Option(..., "--out", help="virtual RINEX 3.04 observation file to write"),
    nav: Optional[Path] = typer.Option(None, "--nav",
                                       help="broadcast navigation file (default: the folder's, e.g. nav.rnx)"),
    coords: Optional[Path] = typer.Option(None, "--coords",
                                          help="station coordinates: NAME X Y Z or NAME LAT LON H per line"),
    exclude: Optional[List[str]] = typer.Option(None, "--exclude",
                                                help="a station to leave out (a rover); repeatable"),
    master: Optional[str] = typer.Option(None, "--master",
                                         help="network master station (default: the most central)"),
    name: str = typer.Option("VRS", "--name", help="marker name of the virtual station"),
    antex: Optional[Path] = typer.Option(None, "--antex",
                                         help="ANTEX file: model the stations' antennas (RINEX header types); "
                                              "the VRS is then for a null antenna (ADVNULLANTENNA)"),
    start: Optional[str] = typer.Option(None, "--start", metavar="HH:MM[:SS]",
                                        help="first epoch to process (GPS time of the data's first day); the "
                                        "network starts cold there"),
    end: Optional[str] = typer.Option(None, "--end", metavar="HH:MM[:SS]", help="last epoch to process"),
    interval: Optional[float] = typer.Option(None, "--interval", metavar="S",
                                             help="write the VRS every S seconds (a 1 Hz rover: 1), epochs "
                                             "between the network's interpolated in time (decision 0222); "
                                             "default: the network's epochs"),
    opt: Optional[List[str]] = typer.Option(None, "--opt", metavar="NAME=VALUE",
                                            help="a network engine setting (docs/options/centre.md); repeatable"),
    admission: str = typer.Option("on", "--admission", metavar="on|off",
                                  help="on: satellites the network newly corrects enter the VRS together at rare "
                                  "admission moments, every satellite restarted there (for rovers without partial "
                                  "AR); off: each enters once corrected (docs/options/vrs.md)"),
    admission_interval_s: Optional[str] = typer.Option(None, "--admission-interval-s", metavar="S",
                                                       help="least time between admission moments, seconds "
                                                       "(defaults: docs/options/vrs.md)"),
    admission_settle_s: Optional[str] = typer.Option(None, "--admission-settle-s", metavar="S",
                                                     help="a moment once the corrected set is this long "
                                                     "unchanged, seconds"),
    admission_min_satellites: Optional[str] = typer.Option(None, "--admission-min-satellites", metavar="N",
                                                           help="... or once this many satellites wait"),
    admission_max_wait_s: Optional[str] = typer.Option(None, "--admission-max-wait-s", metavar="S",
                                                       help="... or once a satellite has waited this long, seconds"),
) -> None:
    """Write a virtual reference station RINEX file for a point from a network's observation files."""
    from augnet.centre.baseline_config import BaselineConfig
    from augnet.centre.postprocess import PostprocessError, run_vrs
    from augnet.centre.vrs_admission import config_from_flags
    from augnet.options import OptionError, with_assignments

    try:
        config = with_assignments(BaselineConfig(), opt or [])
    except OptionError as exc:
        typer.echo(f"error: --opt {exc}", err=True)
        raise typer.Exit(2)
    try:
        admission_config = config_from_flags({"admission": admission, "interval_s": admission_interval_s,
                                              "settle_s": admission_settle_s,
                                              "min_satellites": admission_min_satellites,
                                              "max_wait_s": admission_max_wait_s})
    except OptionError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2)

    step = {"next": 0.0}

    def progress(done: int, total: int) -> None:  # a line on stderr every tenth of the run
        if done / total >= step["next"]:
            typer.echo(f"epoch {done}/{total}", err=True)
            step["next"] += PROGRESS_STEP

    try:
        result, lines = run_vrs(record, at, out, nav=nav, coords=coords, exclude=exclude or (), master=master,
                                marker_name=name, progress=progress, config=config, antex=antex,
                                start=start, end=end, admission=admission_config, interval=interval)
    except PostprocessError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2)
    for line in lines:
        typer.echo(line)
    written = result.epochs if result.written_epochs is None else result.written_epochs
    typer.echo(f"wrote {out}: {len(written)} epochs")
