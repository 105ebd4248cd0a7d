"""Command line: `augnet sim ...` (scenarios, recording) and `augnet stations ...` (live streaming)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import List, Optional

import typer

from stations.scenario import BUILTIN_SCENARIOS, DEFAULT_SCENARIO, ScenarioError, load_scenario, resolved_dict

sim_app = typer.Typer(no_args_is_help=True, help="Simulated world: scenarios and recordings.")
stations_app = typer.Typer(no_args_is_help=True, help="Simulated reference stations and trains, live.")


def _load(scenario: str, duration: Optional[float], seed: Optional[int]):
    try:
        sc = load_scenario(scenario)
    except ScenarioError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2)
    update = {}
    if duration is not None:
        if duration <= 0:
            typer.echo(f"error: --duration must be positive, got {duration}", err=True)
            raise typer.Exit(2)
        update["duration_s"] = duration
    if seed is not None:
        update["seed"] = seed
    return sc.model_copy(update=update) if update else sc


def nav_ephemerides_for(sc, nav_path: Path):
    """Ephemerides from a RINEX nav file, and the scenario moved to the file's day if needed."""
    from augnet.gnss import time as gtime
    from augnet.gnss.ephemeris import NavigationData
    from augnet.gnss.rinex.nav import read_nav

    ephs = [e for e in read_nav(nav_path).ephemerides if e.system in sc.constellations]
    if not ephs:
        raise ScenarioError(f"--nav {nav_path}: no {'/'.join(sc.constellations)} ephemerides in the file")
    nav = NavigationData(ephs)
    t0 = gtime.from_datetime(sc.start)
    if (nav.select(nav.satellites, t0) >= 0).sum() < 4:
        # the scenario's start is not covered: start one hour after the file's first toe, on the hour
        first = min(e.toe_gpst for e in ephs)
        start = gtime.to_datetime(float((first // 3600 + 1) * 3600))
        typer.echo(f"note: {nav_path.name} does not cover {sc.start}; starting at {start} GPST instead", err=True)
        sc = sc.model_copy(update=dict(start=start))
    return sc, ephs


@stations_app.callback()
def _stations() -> None:
    """Simulated reference stations and trains, live (a group even with one command)."""


@sim_app.command("list")
def list_scenarios() -> None:
    """The built-in scenarios."""
    for name in BUILTIN_SCENARIOS:
        sc = load_scenario(name)
        mark = " (default)" if name == DEFAULT_SCENARIO else ""
        typer.echo(f"{name:<15} {sc.description}{mark}")


@sim_app.command("show")
def show(scenario: str = typer.Argument(DEFAULT_SCENARIO, help="built-in name or YAML file")) -> None:
    """Validate a scenario and print it resolved (JSON): every default and preset filled in."""
    sc = _load(scenario, None, None)
    typer.echo(json.dumps(resolved_dict(sc), indent=2, sort_keys=True))


@sim_app.command("survey")
def survey_cmd(layout: str = typer.Option("alpha-beta", "--layout", help="built-in layout or augnet-topology/1 file"),
               seed: int = typer.Option(1, "--seed", help="the run's seed (another seed: an independent run)"),
               gap: List[str] = typer.Option([], "--gap", help="EDGE:FROM_M:TO_M, no positions there (repeatable)"),
               out: Path = typer.Option(..., "--out", help="survey record (augnet-survey/1 JSON)"),
               truth_out: Optional[Path] = typer.Option(None, "--truth", help="also write the truth (outliers)")) -> None:
    """A survey train runs every edge of the layout once, recording GNSS positions with their errors."""
    from stations.layout import Layout, LayoutError
    from stations.survey import survey_run

    try:
        gaps = tuple((g.split(":")[0], float(g.split(":")[1]), float(g.split(":")[2])) for g in gap)
    except (IndexError, ValueError):
        typer.echo(f"error: --gap is EDGE:FROM_M:TO_M, got {gap}", err=True)
        raise typer.Exit(2)
    try:
        lay = Layout.load(layout)
    except LayoutError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2)
    record, truth = survey_run(lay, seed, gaps=gaps)
    out.write_text(json.dumps(record))
    if truth_out is not None:
        truth_out.write_text(json.dumps(truth))
    typer.echo(f"{len(record['runs'])} runs, {sum(len(r['points']) for r in record['runs'])} positions -> {out}")


@sim_app.command("record")
def record_cmd(
    scenario: str = typer.Argument(DEFAULT_SCENARIO, help="built-in name or YAML file"),
    duration: Optional[float] = typer.Option(None, "--duration", help="seconds to simulate"),
    out: Path = typer.Option(Path("runs/sim"), "--out", help="output folder"),
    seed: Optional[int] = typer.Option(None, "--seed", help="override the scenario's seed"),
    nav: Optional[Path] = typer.Option(None, "--nav", help="RINEX 3 nav file instead of the nominal constellation"),
    rtcm: bool = typer.Option(True, "--rtcm/--no-rtcm", help="write <id>.rtcm3 streams"),
) -> None:
    """Run a scenario faster than real time and write RINEX, RTCM, truth and the resolved scenario."""
    from stations.record import record

    sc = _load(scenario, duration, seed)
    ephs = None
    if nav is not None:
        try:
            sc, ephs = nav_ephemerides_for(sc, nav)
        except (ScenarioError, OSError, ValueError) as exc:
            typer.echo(f"error: {exc}", err=True)
            raise typer.Exit(2)
    try:
        summary = record(sc, out, nav_ephemerides=ephs, rtcm=rtcm)
    except ScenarioError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2)
    speed = summary.seconds_simulated / max(summary.seconds_wall, 1e-9)
    typer.echo(f"{sc.name}: {summary.n_epochs} epochs x {len(summary.receivers)} receivers "
               f"({', '.join(summary.receivers)}) in {summary.seconds_wall:.1f} s = {speed:.0f}x real time")
    typer.echo(f"wrote {out}/: {', '.join(summary.files)}")


@sim_app.command("stats")
def stats_cmd(
    rinex: List[Path] = typer.Argument(None, help="RINEX observation files (2 or 3), one per station"),
    nav: Optional[Path] = typer.Option(None, "--nav", help="broadcast navigation file (elevations)"),
    scenario: Optional[str] = typer.Option(None, "--scenario",
                                           help="record this scenario first (to --out) and measure it"),
    duration: Optional[float] = typer.Option(None, "--duration", help="with --scenario: seconds to simulate"),
    rate: Optional[float] = typer.Option(None, "--rate", help="with --scenario: epochs per second"),
    out: Path = typer.Option(Path("runs/sim-stats"), "--out", help="with --scenario: the recording folder"),
    interval: Optional[float] = typer.Option(None, "--interval", help="decimate to this interval [s] first"),
    systems: str = typer.Option("G", "--systems", help="satellite systems measured, e.g. G or GE"),
) -> None:
    """Observation statistics per station (multipath, phase noise, slips, gaps by elevation) and per pair (DD
    ionosphere), the same code for real RINEX and for a simulated recording (stations/observation_statistics.py)."""
    from stations import observation_statistics as ostat
    from stations.calibration import all_pairs, load_nav, measure

    files = list(rinex or [])
    if scenario is not None:
        from stations.record import record

        sc = _load(scenario, duration, None)
        if rate is not None:
            sc = sc.model_copy(update=dict(rate_hz=rate))
        record(sc.model_copy(update=dict(trains=[])), out, rtcm=False)
        files += [out / f"{s.id}.obs" for s in sc.stations]
        nav = nav or out / "nav.rnx"
    if not files:
        typer.echo("error: give RINEX files or --scenario", err=True)
        raise typer.Exit(2)
    try:
        navdata = load_nav(nav) if nav is not None else None
        series = {}
        for f in files:
            s = ostat.load_station(f, navdata, None if scenario is None else f.stem, tuple(systems))
            series[s.name] = s.decimated(interval) if interval else s
    except (OSError, ValueError) as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2)
    st, pr = measure(series, all_pairs(list(series)))
    typer.echo(ostat.station_table([(str(f.name), st[n]) for f, n in zip(files, series)]))
    typer.echo("")
    typer.echo(ostat.pair_table([("", p) for p in pr.values()]))
    if navdata is None:
        typer.echo("(no --nav: no elevations, so no figures by elevation and no DD ionosphere)", err=True)


@sim_app.command("calibrate")
def calibrate_cmd(
    real: Path = typer.Option(..., "--real", help="the catnet-2010-077 folder (RINEX 2 + brdc0770.10n.gz)"),
    work: Path = typer.Option(Path("runs/calibration"), "--work", help="folder for the presets' recordings"),
) -> None:
    """The presets beside the real network's statistics: the tables of docs/simulator-calibration.md."""
    from stations.calibration import calibration_report

    typer.echo(calibration_report(real, work, log=lambda m: typer.echo(m, err=True)))


@stations_app.command("run")
def run_cmd(
    scenario: str = typer.Argument(DEFAULT_SCENARIO, help="built-in name or YAML file"),
    caster: str = typer.Option(..., "--caster", help="HOST:PORT of the NTRIP caster"),
    password: str = typer.Option("", "--password", help="source password (NTRIP 1) / credentials"),
    user: str = typer.Option("", "--user", help="NTRIP 2 user"),
    duration: Optional[float] = typer.Option(None, "--duration", help="seconds to stream"),
    speed: float = typer.Option(1.0, "--speed", help="playback speed (1 = real time)"),
) -> None:
    """Stream every station (mountpoint = its id) and train (TRAIN-<id>-RAW) to an NTRIP caster."""
    import asyncio

    from stations.live import run_stations

    sc = _load(scenario, duration, None)
    host, _, port = caster.rpartition(":")
    if not host or not port.isdigit():
        typer.echo(f"error: --caster must be HOST:PORT, got {caster!r}", err=True)
        raise typer.Exit(2)
    asyncio.run(run_stations(sc, host, int(port), user=user, password=password, speed=speed))


__all__ = ["sim_app", "stations_app"]
