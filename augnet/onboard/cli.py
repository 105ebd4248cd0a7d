"""`augnet rtk`: post-process RTK like RTKLIB's rnx2rtkp, writing the solution CSV (see solution.py).

    augnet rtk --rover R.obs --base B.obs --nav N.nav --base-pos X,Y,Z|LAT,LON,H --out sol.csv

`--base-pos header` takes the base file's APPROX POSITION.  `--antex FILE` models both receivers' antennas
from their RINEX headers (ANT # / TYPE looked up in the ANTEX file, ANTENNA: DELTA H/E/N): the base position
and the solution are then the markers', as RTKLIB's with ant1/ant2-anttype=*.  `--opt NAME=VALUE` (repeatable) sets any
field of the settings table `RtkOptions` (docs/options/rtk.md), after the flags.  `--base-interp` interpolates
a slower base's observations to each rover epoch (base_interpolation.py; rnx2rtkp's misc-timeinterp).  Exit status 0 when every
epoch was processed (whatever its status), 2 for unusable inputs.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Annotated

import typer

SYSTEM_LETTERS = "GECJ"


def rtk(
    rover: Annotated[Path, typer.Option("--rover", help="rover RINEX observation file")],
    base: Annotated[Path, typer.Option("--base", help="base RINEX observation file")],
    nav: Annotated[list[Path], typer.Option("--nav", help="RINEX 3 navigation file (repeatable)")],
    out: Annotated[Path, typer.Option("--out", help="solution CSV to write ('-' for stdout)")],
    base_pos: Annotated[str, typer.Option("--base-pos", help="X,Y,Z (ECEF m) or LAT,LON,H (deg, m), or 'header'")] = "header",
    mode: Annotated[str, typer.Option("--mode", help="kinematic or static")] = "kinematic",
    elevation_mask: Annotated[float, typer.Option("--elevation-mask", help="degrees")] = 15.0,
    systems: Annotated[str, typer.Option("--systems", help="system letters, e.g. GEC or GEJ")] = "GECJ",
    frequencies: Annotated[int, typer.Option("--frequencies", help="1 = L1/E1/B1I, 2 = dual, 3 = triple")] = 2,
    ratio: Annotated[float, typer.Option("--ratio", help="ratio-test threshold")] = 3.0,
    success_rate: Annotated[float, typer.Option("--success-rate", help="minimum bootstrapped success rate")] = 0.999,
    max_age: Annotated[float, typer.Option("--max-age", help="maximum age of corrections [s]")] = 5.0,
    dynamics: Annotated[bool, typer.Option("--dynamics/--no-dynamics", help="kinematic: position-velocity-acceleration model")] = False,
    hold: Annotated[bool, typer.Option("--hold/--no-hold", help="fix-and-hold")] = True,
    base_kind: Annotated[str, typer.Option("--base-kind", help="auto (the base file's MARKER TYPE: NON_PHYSICAL is a "
                                           "VRS), station, or vrs (estimate the network's residual ionosphere)")] = "auto",
    antex: Annotated[Path | None, typer.Option("--antex", help="ANTEX file: model base and rover antennas from "
                                              "their RINEX headers (ANT # / TYPE, DELTA H/E/N); positions are "
                                              "then the markers'")] = None,
    opt_assignments: Annotated[list[str] | None, typer.Option("--opt", help="NAME=VALUE: any RTK setting "
                                                              "(docs/options/rtk.md); repeatable")] = None,
    start: Annotated[str | None, typer.Option("--start", help="first rover epoch, GPST 'YYYY-MM-DDTHH:MM:SS' "
                                              "(rnx2rtkp -ts)")] = None,
    end: Annotated[str | None, typer.Option("--end", help="rover epochs before this, GPST 'YYYY-MM-DDTHH:MM:SS' "
                                            "(rnx2rtkp -te)")] = None,
    base_interp: Annotated[bool, typer.Option("--base-interp/--no-base-interp",
                                              help="interpolate the base's observations to each rover epoch "
                                              "between two base epochs (rnx2rtkp misc-timeinterp; files only)")] = False,
) -> None:
    """Post-process RTK: rover + base RINEX -> solution CSV (time, ECEF, geodetic, status, ratio, sigmas)."""
    from augnet.onboard.inputs import (InputError, antenna_setup, load_nav, load_obs, parse_gpst, parse_position,
                                       time_window)
    from augnet.onboard.base_interpolation import MAX_INTERPOLATION_SPAN_S
    from augnet.onboard.ionosphere_prior import BASE_RATE_SPAN_S
    from augnet.onboard.postprocess import process
    from augnet.onboard.rtk import RtkOptions
    from augnet.onboard.solution import write_csv
    from augnet.onboard.spp import SppOptions
    from augnet.options import OptionError, with_assignments

    if mode not in ("kinematic", "static"):
        raise typer.BadParameter("mode must be kinematic or static", param_hint="--mode")
    sys_ = tuple(c for c in systems.upper() if c in SYSTEM_LETTERS)
    if not sys_:
        raise typer.BadParameter(f"no known system among {systems!r} (use {SYSTEM_LETTERS})", param_hint="--systems")
    if not 1 <= frequencies <= 3:
        raise typer.BadParameter("1, 2 or 3", param_hint="--frequencies")
    if base_kind not in ("auto", "station", "vrs"):
        raise typer.BadParameter("auto, station or vrs", param_hint="--base-kind")
    opt = RtkOptions(
        mode=mode, dynamics=dynamics, elevation_mask_rad=math.radians(elevation_mask), systems=sys_,
        n_slots=frequencies, ratio_threshold=ratio, min_success_rate=success_rate, max_age_s=max_age,
        fix_and_hold=hold,
        spp=SppOptions(elevation_mask_rad=math.radians(min(elevation_mask, 10.0)), systems=sys_),
    )
    try:
        opt = with_assignments(opt, opt_assignments or [])
    except OptionError as exc:
        raise typer.BadParameter(str(exc), param_hint="--opt") from None
    try:
        navdata, alpha, beta = load_nav(nav)
        opt.spp.klobuchar_alpha, opt.spp.klobuchar_beta = alpha, beta
        rov = load_obs(rover)
        bas = load_obs(base)
        if start is not None or end is not None:
            t0 = parse_gpst(start) if start is not None else -math.inf
            t1 = parse_gpst(end) if end is not None else math.inf
            rov = time_window(rov, t0, t1)
            # the base epoch in force at the first rover epoch is the latest before it
            # ... and its past before it, the quiet-ionosphere rate's base part (decision 0221)
            bas = time_window(bas, t0 - max(opt.max_age_s + 1.0, BASE_RATE_SPAN_S),
                              t1 + (MAX_INTERPOLATION_SPAN_S if base_interp else 0.0))
        if base_pos.strip().lower() == "header":
            bp = bas.approx_position_m
            if bp is None or not 6.0e6 < float((bp**2).sum()) ** 0.5 < 7.0e6:
                raise InputError("the base file has no usable APPROX POSITION XYZ; give --base-pos")
        else:
            bp = parse_position(base_pos)
        antennas = {}
        if antex is not None:
            from augnet.gnss.antex import AntexError, read_antex

            try:
                atx = read_antex(antex)
            except AntexError as exc:
                raise InputError(f"--antex: {exc}") from None
            for what, obs in (("base", bas), ("rover", rov)):
                antennas[what], note = antenna_setup(obs, atx, what)
                typer.echo(f"augnet rtk: {note}", err=True)
    except InputError as exc:
        typer.echo(f"augnet rtk: {exc}", err=True)
        raise typer.Exit(2)
    sols = process(rov, bas, navdata, bp, opt, base_is_vrs=None if base_kind == "auto" else base_kind == "vrs",
                   base_antenna=antennas.get("base"), rover_antenna=antennas.get("rover"), interpolate_base=base_interp)
    counts: dict[str, int] = {}

    def counted():
        for s in sols:
            counts[s.status_name] = counts.get(s.status_name, 0) + 1
            yield s

    if str(out) == "-":
        n = write_csv(counted(), sys.stdout)
    else:
        with open(out, "w", encoding="ascii", errors="replace", newline="") as f:
            n = write_csv(counted(), f)
    summary = ", ".join(f"{k} {v}" for k, v in sorted(counts.items()))
    typer.echo(f"augnet rtk: {n} epochs ({summary})", err=True)
