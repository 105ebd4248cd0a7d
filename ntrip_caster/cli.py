"""`ntrip-caster serve ...` / `augnet caster ...`: run the caster, hash passwords, print the table."""

from __future__ import annotations

import asyncio
import json
import logging
import signal
import sys
from dataclasses import replace
from pathlib import Path
from typing import Optional

import typer

from augwire.passwords import hash_password

from .config import CasterConfig, ConfigError, load_config

app = typer.Typer(help="NTRIP 1.0 / 2.0 caster.", no_args_is_help=True, add_completion=False)


def _config(config: Optional[Path], host: Optional[str], port: Optional[int],
            allow_unknown_sources: Optional[bool], stats_path: Optional[str]) -> CasterConfig:
    try:
        cfg = load_config(config) if config else CasterConfig(allow_unknown_sources=True)
    except ConfigError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2)
    changes: dict = {}
    if host is not None:
        changes["host"] = host
    if port is not None:
        changes["port"] = port
    if allow_unknown_sources is not None:
        changes["allow_unknown_sources"] = allow_unknown_sources
    if stats_path is not None:
        changes["stats_path"] = stats_path
    return replace(cfg, **changes)


def _raise_fd_limit() -> None:
    """One descriptor per client: lift the soft limit to the hard one (as nginx's
    worker_rlimit_nofile does) so 10,000 trains do not hit EMFILE at the default 1,024."""
    try:
        import resource

        soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
        if hard == resource.RLIM_INFINITY or soft < hard:
            resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))
    except (ImportError, ValueError, OSError):
        pass


@app.command()
def serve(
    config: Optional[Path] = typer.Option(None, "--config", "-c", help="TOML or YAML file; without "
                                          "one, an open caster that accepts any source."),
    host: Optional[str] = typer.Option(None, help="Bind address (default 127.0.0.1)."),
    port: Optional[int] = typer.Option(None, help="TCP port (default 2101; 0 picks one)."),
    allow_unknown_sources: Optional[bool] = typer.Option(
        None, "--allow-unknown-sources/--no-unknown-sources",
        help="Accept sources for mountpoints not in the config."),
    stats_path: Optional[str] = typer.Option(None, help="Write a JSON stats snapshot here."),
    uvloop: bool = typer.Option(True, "--uvloop/--no-uvloop", help="Use uvloop when installed."),
    ready_file: Optional[Path] = typer.Option(None, help="Write the bound port here once listening."),
    log_level: str = typer.Option("INFO", help="DEBUG, INFO, WARNING, ERROR."),
) -> None:
    """Run the caster until SIGINT/SIGTERM, then shut down gracefully."""
    from .embedded import new_event_loop
    from .server import Caster

    logging.basicConfig(level=log_level.upper(), format="%(asctime)s %(name)s %(levelname)s %(message)s")
    _raise_fd_limit()
    cfg = _config(config, host, port, allow_unknown_sources, stats_path)
    try:
        caster = Caster(cfg)
    except (ValueError, ImportError, AttributeError) as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2)

    async def run() -> None:
        bound = await caster.start()
        if ready_file is not None:
            ready_file.write_text(str(bound))
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        await stop.wait()
        await caster.stop()

    loop = new_event_loop(uvloop)
    try:
        loop.run_until_complete(run())
    except OSError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(1)
    finally:
        loop.close()


@app.command("hash-password")
def hash_password_cmd(
    password: Optional[str] = typer.Option(None, help="Read from a prompt when omitted."),
) -> None:
    """Print the scrypt hash to put in a user's password_hash."""
    if password is None:
        password = typer.prompt("password", hide_input=True, confirmation_prompt=True)
    typer.echo(hash_password(password))


@app.command()
def sourcetable(config: Path = typer.Option(..., "--config", "-c")) -> None:
    """Print the sourcetable a configuration produces (every mountpoint, as if live)."""
    from .sourcetable import CasRecord, render_sourcetable

    cfg = _config(config, None, None, None, None)
    records: list = [CasRecord(cfg.host, cfg.port, cfg.identifier, cfg.operator, 0, cfg.country)]
    records += [m.str_record() for m in cfg.mounts]
    sys.stdout.write(render_sourcetable(records).decode())


@app.command()
def check(config: Path = typer.Option(..., "--config", "-c")) -> None:
    """Validate a configuration file and print a summary as JSON."""
    cfg = _config(config, None, None, None, None)
    typer.echo(json.dumps({"host": cfg.host, "port": cfg.port, "users": sorted(cfg.users),
                           "mountpoints": {m.name: m.kind for m in cfg.mounts}}))


def main() -> None:
    app()


if __name__ == "__main__":
    main()
