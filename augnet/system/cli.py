"""`augnet up [SCENARIO] [--trains N] [--duration S] [--db URL]`: the whole system in one process."""

from __future__ import annotations

import asyncio
import logging
import sys
from pathlib import Path
from typing import Optional

import typer

from augnet.system.baseline_quality import FIXED_BASELINE_FRACTION
from augnet.system.settings import (DEFAULT_CASTER_PORT, DEFAULT_CONSOLE_PORT, DEFAULT_DB_URL, SettingsError,
                                    SystemSettings)


def up(
    scenario: str = typer.Argument("demo", help="Scenario name (stations/scenarios) or a YAML file."),
    trains: Optional[int] = typer.Option(None, help="Number of simulated trains (default: the scenario's)."),
    duration: Optional[float] = typer.Option(None, help="Stop by itself after this many seconds and write the run report."),
    db: str = typer.Option(DEFAULT_DB_URL, envvar="AUGNET_DB_URL",
                           help="Store URL: SQLite file (default) or postgresql://..."),
    host: str = typer.Option("127.0.0.1", help="Address the caster and console listen on."),
    caster_port: int = typer.Option(DEFAULT_CASTER_PORT, help="NTRIP caster port."),
    console_port: int = typer.Option(DEFAULT_CONSOLE_PORT, help="Operator console port (0: no console)."),
    bus: str = typer.Option("", envvar="AUGNET_BUS_URL",
                            help="Correction bus: empty = in-process, or nats://HOST:PORT (JetStream)."),
    rbc: bool = typer.Option(True, "--rbc/--no-rbc", help="Run the RSSP-I link to the RBC simulator."),
    view: bool = typer.Option(True, "--view/--no-view", help="Live terminal view (off: log lines)."),
    report: Optional[Path] = typer.Option(None, help="Run report path (default with --duration: augnet-run-report.json)."),
    state: Path = typer.Option(Path("augnet-up.json"), help="Where tools find the URLs and credentials of this run."),
    admin_password: str = typer.Option("", envvar="AUGNET_ADMIN_PASSWORD",
                                       help="Console admin password (first run; default: random, written to the state file)."),
    service_radius_km: Optional[float] = typer.Option(
        None, help="VRS served up to this far from the nearest station (default: the largest station spacing)."),
    outside_area: str = typer.Option("refuse", help="A client outside the service area: refuse, or nearest "
                                                    "(the nearest station's stream)."),
    admission: str = typer.Option("on", "--admission", metavar="on|off",
                                  help="on: satellites the network newly corrects enter each train's VRS together at "
                                  "rare admission moments, every satellite restarted there (for rovers without "
                                  "partial AR); off: each enters once corrected (docs/options/vrs.md)."),
    admission_interval_s: Optional[str] = typer.Option(None, "--admission-interval-s", metavar="S",
                                                       help="Least time between admission moments, seconds."),
    admission_settle_s: Optional[str] = typer.Option(None, "--admission-settle-s", metavar="S",
                                                     help="A moment once the corrected set is this long unchanged."),
    admission_min_satellites: Optional[str] = typer.Option(None, "--admission-min-satellites", metavar="N",
                                                           help="... or once this many satellites wait."),
    admission_max_wait_s: Optional[str] = typer.Option(None, "--admission-max-wait-s", metavar="S",
                                                       help="... or once a satellite has waited this long."),
) -> None:
    """Stations, caster, centre, RSSP-I link, trains and console in one asyncio process."""
    from augnet.centre.vrs_admission import config_from_flags
    from augnet.options import OptionError

    try:
        admission_config = config_from_flags({"admission": admission, "interval_s": admission_interval_s,
                                              "settle_s": admission_settle_s,
                                              "min_satellites": admission_min_satellites,
                                              "max_wait_s": admission_max_wait_s})
    except OptionError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2)
    settings = SystemSettings(scenario=scenario, trains=trains, duration_s=duration, db_url=db, host=host,
                              caster_port=caster_port, console_port=console_port, bus_url=bus, rbc=rbc,
                              view=view, report_path=report, state_path=state, admin_password=admin_password,
                              service_radius_km=service_radius_km, outside_area=outside_area,
                              admission=admission_config)
    try:
        settings.validate()
        from stations.scenario import load_scenario
        load_scenario(scenario)
    except SettingsError as exc:
        typer.echo(f"error: --{exc}", err=True)
        raise typer.Exit(2)
    except Exception as exc:  # noqa: BLE001 - an unknown scenario or a bad file: say which
        typer.echo(f"error: scenario {scenario!r}: {exc}", err=True)
        raise typer.Exit(2)
    logging.basicConfig(level=logging.WARNING, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    from ntrip_caster.embedded import new_event_loop

    with asyncio.Runner(loop_factory=new_event_loop) as runner:  # uvloop: the caster's writes cost less
        summary = runner.run(_main(settings))
    if summary is None:
        raise typer.Exit(1)
    if duration:
        path = report or Path("augnet-run-report.json")
        path.write_text(summary.to_json())
        typer.echo(f"run report: {path}")
    fixed = [t for t, v in summary.trains.items() if v["holds_fix"]]
    typer.echo(f"stopped after {summary.duration_s:.0f} s: {summary.network_epochs} network epochs, "
               f"trains holding a fix at the end: {', '.join(fixed) or 'none'}")


async def _main(settings: SystemSettings):
    from augnet.system.runtime import System

    system = System(settings)
    runner = asyncio.ensure_future(system.run(settings.duration_s))
    ready = asyncio.ensure_future(system.ready.wait())
    await asyncio.wait([runner, ready], return_when=asyncio.FIRST_COMPLETED)
    if runner.done():
        try:
            return runner.result()
        except OSError as exc:
            print(f"error: {exc} (is another augnet up running? use --caster-port / --console-port)", file=sys.stderr)
            return None
    print(f"augnet up: scenario {settings.scenario}, {len(system.trains)} trains", flush=True)
    print(f"console: {system.console_url or 'off'}", flush=True)
    where = settings.state_path or "no state file (--state)"
    if system.admin_password_created:
        print(f"console admin account created: admin, password in {where}", flush=True)
    if system.admin_token:
        print(f"console admin token (open the page with {system.console_url}#token=TOKEN): in {where}", flush=True)
    print(f"caster: ntrip://127.0.0.1:{system.caster.port}/VRS (user {system.credentials['train_user']}, "
          f"password in {settings.state_path})", flush=True)
    if settings.view and sys.stdout.isatty():
        from augnet.system.view import run_view
        view = asyncio.ensure_future(run_view(system))
    else:
        view = asyncio.ensure_future(_log_lines(system))
    try:
        return await runner
    finally:
        view.cancel()


async def _log_lines(system, every_s: float = 10.0) -> None:
    """Without a terminal: one status line every `every_s`."""
    while not system.stop_event.is_set():
        await asyncio.sleep(every_s)
        r = system.publisher.last_report
        trains = " ".join(f"{tid}:{(t.last.solution.status_name if t.last else '-')}"
                          for tid, t in sorted(system.trains.items()))
        fixed = r.network.fixed_fraction() if r else {}
        print(f"[{system.settings.scenario}] epochs {system.centre.timings.epochs} stations "
              f"{len(r.network.present) if r else 0}/{len(system.centre.stations)} baselines fixed "
              f"{sum(v >= FIXED_BASELINE_FRACTION for v in fixed.values())}/{len(fixed)} trains {trains}", flush=True)
