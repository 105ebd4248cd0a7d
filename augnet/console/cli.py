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
DEFAULT_STATE = "augnet-console.json"  # `console serve`'s state file
UP_STATE = "augnet-up.json"  # `augnet up`'s (augnet.system.settings)


@app.command()
def serve(db: str = typer.Option(DEFAULT_URL, "--db", help="store URL: sqlite:///FILE or postgresql://..."),
          host: str = typer.Option(DEFAULT_HOST, "--host"),
          port: int = typer.Option(DEFAULT_PORT, "--port", min=1, max=65535),
          admin: str = typer.Option("admin", "--admin", help="name of the first admin, created if the store has none"),
          state: Path = typer.Option(Path(DEFAULT_STATE), "--state",
                                     help="state file (0600): the console URL, the store's bootstrap token, a new "
                                          "admin's password"),
          ) -> None:
    """Serve the console over a store with no live system (the live sections stay empty)."""
    import uvicorn

    from augnet.console.app import create_app
    from augnet.console.security import bootstrap_admin
    from augnet.console.statefile import read_state, write_private
    from augnet.store import open_store

    sessions = open_store(db)
    boot = bootstrap_admin(sessions, admin, previous=read_state(state))
    url = f"http://{host}:{port}/"
    if boot is not None:
        info = {"console_url": url, "admin_name": boot.name, "admin_token": boot.token}
        if boot.password:
            info["admin_password"] = boot.password
        write_private(state, info)
        if boot.created:
            typer.echo(f"created admin account {boot.name!r}: password in {state}")
        typer.echo(f"admin token in {state}; open the page with {url}#token=TOKEN")
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
def token(name: str = typer.Argument(None, help="operator name (with --rotate: the bootstrap token's new holder)"),
          db: str = typer.Option(DEFAULT_URL, "--db"),
          hours: float = typer.Option(12.0, "--hours", min=0.0, help="lifetime; 0 = never expires"),
          rotate: bool = typer.Option(False, "--rotate", help="replace the store's bootstrap token (the one in "
                                                              "the state file); the old one stops working"),
          state: Path = typer.Option(None, "--state", help="with --rotate: the state file to write the new token "
                                                           "to (default: augnet-up.json if it exists)")) -> None:
    """Issue an API token for an operator (printed once; only its hash is stored), or rotate the bootstrap
    token (written to the state file, printed only when there is none)."""
    from augnet.console.security import issue_operator_token, rotate_bootstrap
    from augnet.console.statefile import update_state
    from augnet.store import open_store
    from augnet.store import queries as q

    if not rotate and not name:
        raise typer.BadParameter("give an operator name, or --rotate", param_hint="NAME")
    try:
        if rotate:
            boot = rotate_bootstrap(open_store(db), name)
        else:
            tok = issue_operator_token(open_store(db), name, lifetime=dt.timedelta(hours=hours) if hours else None)
    except (q.NotFound, q.Conflict) as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(1)
    if not rotate:
        typer.echo(tok)
        return
    if state is None and Path(UP_STATE).exists():
        state = Path(UP_STATE)
    if state is None:
        typer.echo(boot.token)
        return
    update_state(state, admin_token=boot.token, admin_name=boot.name)
    typer.echo(f"bootstrap token of {boot.name} rotated: the new one is in {state}")


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
