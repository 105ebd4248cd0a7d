"""`augnet console ...`: serve the console over a store, manage operator accounts, benchmark it."""

from __future__ import annotations

import datetime as dt
import getpass
import json
from pathlib import Path

import typer

from augnet.store import DEFAULT_URL

app = typer.Typer(help="The operator console.", no_args_is_help=True, add_completion=False)

DEFAULT_PORT = 8000
DEFAULT_HOST = "127.0.0.1"


@app.command()
def serve(db: str = typer.Option(DEFAULT_URL, "--db", help="store URL: sqlite:///FILE or postgresql://..."),
          host: str = typer.Option(DEFAULT_HOST, "--host"),
          port: int = typer.Option(DEFAULT_PORT, "--port", min=1, max=65535),
          admin: str = typer.Option("admin", "--admin", help="name of the first admin, created if the store has none"),
          ) -> None:
    """Serve the console over a store with no live system (the live sections stay empty)."""
    import uvicorn

    from augnet.console.app import create_app
    from augnet.console.security import ensure_admin
    from augnet.store import open_store

    sessions = open_store(db)
    boot = ensure_admin(sessions, admin)
    if boot is not None:
        typer.echo(f"created admin account {boot.name!r} password {boot.password!r}")
        typer.echo(f"admin API token: {boot.token}")
        typer.echo(f"page: http://{host}:{port}/#token={boot.token}")
    uvicorn.run(create_app(sessions), host=host, port=port, log_level="warning")


@app.command("add-operator")
def add_operator(name: str = typer.Argument(...),
                 role: str = typer.Option("viewer", "--role", help="viewer | operator | admin"),
                 db: str = typer.Option(DEFAULT_URL, "--db"),
                 password: str = typer.Option(None, "--password", help="prompted for when not given")) -> None:
    """Create an operator account (audited as done by `system`)."""
    from augnet.console.schemas import MIN_PASSWORD_CHARS
    from augnet.console.security import SYSTEM_ACTOR
    from augnet.store import open_store
    from augnet.store import queries as q
    from augnet.store.models import Role
    from augwire.passwords import hash_password

    try:
        role_value = Role(role)
    except ValueError:
        raise typer.BadParameter(f"role must be one of {[r.value for r in Role]}", param_hint="--role")
    if password is None:
        password = getpass.getpass(f"password for {name}: ")
    if len(password) < MIN_PASSWORD_CHARS:
        raise typer.BadParameter(f"at least {MIN_PASSWORD_CHARS} characters", param_hint="--password")
    sessions = open_store(db)
    try:
        with sessions.begin() as s:
            q.add_operator(s, SYSTEM_ACTOR, name, hash_password(password), role_value)
    except q.Conflict as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(1)
    typer.echo(f"operator {name} ({role_value.value}) created")


@app.command()
def token(name: str = typer.Argument(..., help="operator name"),
          db: str = typer.Option(DEFAULT_URL, "--db"),
          hours: float = typer.Option(12.0, "--hours", min=0.0, help="lifetime; 0 = never expires")) -> None:
    """Issue an API token for an operator (printed once; only its hash is stored)."""
    from augnet.console.security import issue_operator_token
    from augnet.store import open_store
    from augnet.store import queries as q

    try:
        tok = issue_operator_token(open_store(db), name, lifetime=dt.timedelta(hours=hours) if hours else None)
    except q.NotFound as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(1)
    typer.echo(tok)


@app.command()
def bench(url: str = typer.Option("http://127.0.0.1:8000", "--url"),
          token: str = typer.Option(None, "--token", help="any operator's API token (viewer suffices)"),
          state: Path = typer.Option(None, "--state", help="the state file `augnet up` writes (augnet-up.json): "
                                                           "its console URL and admin token"),
          requests: int = typer.Option(200, "--requests", min=10, help="timed requests per route")) -> None:
    """p50 / p99 response time of the main GET routes of a running console (goal: p99 <= 50 ms)."""
    import httpx

    from augnet.console.bench import P99_GOAL_MS, measure, overall

    if state is not None:
        try:
            info = json.loads(state.read_text())
            url, token = info["console_url"], token or info["admin_token"]
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise typer.BadParameter(f"cannot read console_url and admin_token from {state}: {exc}",
                                     param_hint="--state")
    if not token:
        raise typer.BadParameter("give --token, or --state with an admin token", param_hint="--token")
    try:
        timings = measure(url, token, requests)
    except httpx.HTTPError as exc:
        typer.echo(f"error: cannot reach the console at {url}: {exc}", err=True)
        raise typer.Exit(2)
    typer.echo(f"{'route':32s} {'n':>5s} {'p50 ms':>8s} {'p99 ms':>8s} {'max ms':>8s} {'errors':>6s}")
    for t in timings:
        typer.echo(f"{t.route:32s} {t.n:5d} {t.p50_ms:8.2f} {t.p99_ms:8.2f} {t.max_ms:8.2f} {t.errors:6d}")
    p50, p99 = overall(timings)
    errors = sum(t.errors for t in timings)
    verdict = "meets" if p99 <= P99_GOAL_MS else "MISSES"
    typer.echo(f"worst route p50 {p50:.2f} ms, p99 {p99:.2f} ms: {verdict} the {P99_GOAL_MS:.0f} ms p99 goal"
               + (f"; {errors} non-200 answers" if errors else ""))
    if errors:
        raise typer.Exit(1)
