"""`augnet console ...` commands and the response-time benchmark, against a console served over loopback."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from augnet.console.app import create_app
from augnet.console.bench import MAIN_GET_ROUTES, measure, overall, percentile
from augnet.console.cli import app as console_app
from augnet.console.live import LiveState, TrainLive
from augnet.console.server import ConsoleThread
from augnet.store import open_store
from augnet.store import queries as q

BENCH_REQUESTS = 20  # per route: enough to exercise the code, not a measurement


def test_percentile_nearest_rank():
    values = list(range(1, 201))  # 1..200
    assert percentile(values, 50) == 100 and percentile(values, 99) == 198 and percentile(values, 100) == 200
    assert percentile([5.0], 99) == 5.0
    with pytest.raises(ValueError):
        percentile([], 50)


def test_add_operator_and_token_commands(tmp_path):
    url = f"sqlite:///{tmp_path / 'cli.sqlite'}"
    runner = CliRunner()
    r = runner.invoke(console_app, ["add-operator", "otto", "--role", "operator", "--db", url,
                                    "--password", "operator-secret"])
    assert r.exit_code == 0, r.output
    assert "otto (operator) created" in r.output
    again = runner.invoke(console_app, ["add-operator", "otto", "--db", url, "--password", "operator-secret"])
    assert again.exit_code == 1 and "exists" in again.output
    bad_role = runner.invoke(console_app, ["add-operator", "x", "--role", "root", "--db", url, "--password", "12345678"])
    assert bad_role.exit_code == 2 and "role" in bad_role.output
    short = runner.invoke(console_app, ["add-operator", "y", "--db", url, "--password", "short"])
    assert short.exit_code == 2
    r = runner.invoke(console_app, ["token", "otto", "--db", url])
    assert r.exit_code == 0, r.output
    token = r.output.strip()
    sessions = open_store(url)
    with sessions() as s:
        assert q.operator_for_token(s, token).name == "otto"
        assert [e.action for e in q.audit_log(s, 2)] == ["token.issue", "operator.add"]
    missing = runner.invoke(console_app, ["token", "nobody", "--db", url])
    assert missing.exit_code == 1 and "no operator nobody" in missing.output


def test_console_mounted_under_augnet():
    from augnet import cli

    cli._mount()
    r = CliRunner().invoke(cli.app, ["console", "--help"])
    assert r.exit_code == 0
    for command in ("serve", "bench", "token", "add-operator"):
        assert command in r.output


@pytest.mark.slow
def test_bench_measures_every_main_route(tmp_path):
    sessions = open_store(f"sqlite:///{tmp_path / 'bench.sqlite'}")
    from augnet.console.security import ensure_admin

    boot = ensure_admin(sessions)
    live = LiveState()
    for i in range(20):
        live.update_train(TrainLive(f"T{i}", 30.0, 114.0, 20.0, "L1", float(i), 0.0, "fix", 1.0, 0.1, 0.2, 100.0))
    with ConsoleThread(create_app(sessions, live)) as server:
        timings = measure(server.url, boot.token, BENCH_REQUESTS)
        assert [t.route for t in timings] == list(MAIN_GET_ROUTES)
        assert all(t.errors == 0 and t.n == BENCH_REQUESTS for t in timings)
        assert all(0 < t.p50_ms <= t.p99_ms <= t.max_ms for t in timings)
        p50, p99 = overall(timings)
        assert p99 == max(t.p99_ms for t in timings)
        # a wrong token: every request is an error, and the command says so
        bad = measure(server.url, "wrong", 10, routes=("/api/trains",))
        assert bad[0].errors == 10
        r = CliRunner().invoke(console_app, ["bench", "--url", server.url, "--token", boot.token,
                                             "--requests", "10"])
        assert r.exit_code == 0, r.output
        assert "/api/trains" in r.output and "p99 goal" in r.output
        r = CliRunner().invoke(console_app, ["bench", "--url", server.url, "--token", "wrong", "--requests", "10"])
        assert r.exit_code == 1 and "non-200" in r.output
        # the state file `augnet up` writes gives the URL and the admin token
        state = tmp_path / "augnet-up.json"
        state.write_text(json.dumps({"console_url": server.url + "/", "admin_token": boot.token}))
        r = CliRunner().invoke(console_app, ["bench", "--state", str(state), "--requests", "10"])
        assert r.exit_code == 0 and "/metrics" in r.output, r.output
        state.write_text("{}")
        r = CliRunner().invoke(console_app, ["bench", "--state", str(state), "--requests", "10"])
        assert r.exit_code == 2 and "console_url" in r.output
        assert CliRunner().invoke(console_app, ["bench", "--url", server.url]).exit_code == 2  # no token
    r = CliRunner().invoke(console_app, ["bench", "--url", server.url, "--token", boot.token, "--requests", "10"])
    assert r.exit_code == 2 and "cannot reach" in r.output


@pytest.mark.slow
def test_serve_command_bootstraps_an_admin_and_serves(tmp_path):
    import socket
    import subprocess
    import sys
    import time

    import httpx

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    url = f"sqlite:///{tmp_path / 'serve.sqlite'}"
    state_file = tmp_path / "console.json"
    proc = subprocess.Popen([sys.executable, "-m", "augnet", "console", "serve", "--db", url, "--port", str(port),
                             "--state", str(state_file)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        lines = [proc.stdout.readline() for _ in range(2)]
        assert lines[0].strip() == f"created admin account 'admin': password in {state_file}", lines
        assert lines[1].strip() == f"admin token in {state_file}; open the page with http://127.0.0.1:{port}/#token=TOKEN"
        state = json.loads(state_file.read_text())
        assert state_file.stat().st_mode & 0o777 == 0o600
        token, password = state["admin_token"], state["admin_password"]
        assert token not in "".join(lines) and password not in "".join(lines)  # secrets in the file, not on stdout
        deadline = time.monotonic() + 20
        while True:
            try:
                r = httpx.get(f"http://127.0.0.1:{port}/api/auth/me", headers={"Authorization": f"Bearer {token}"})
                break
            except httpx.ConnectError:
                assert time.monotonic() < deadline and proc.poll() is None, "console did not come up"
                time.sleep(0.1)
        assert r.status_code == 200 and r.json()["role"] == "admin"
        page = httpx.get(f"http://127.0.0.1:{port}/")
        assert page.status_code == 200 and "augnet console" in page.text
        js = httpx.get(f"http://127.0.0.1:{port}/static/console.js")
        assert js.status_code == 200 and "WebSocket" in js.text
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def test_page_has_no_external_assets():
    import re

    from augnet.console.routers.page import STATIC_DIR

    files = sorted(STATIC_DIR.iterdir())
    assert {f.name for f in files} >= {"index.html", "console.js", "console.css"}
    for f in files:
        text = f.read_text()
        urls = set(re.findall(r"(?:https?:)?//[A-Za-z0-9.-]+\.[a-z]{2,}[^\s\"')]*", text))
        assert urls <= {"http://www.w3.org/2000/svg"}, (f.name, urls)  # the SVG namespace is a name, not a fetch
        assert "@import" not in text and "cdn" not in text.lower()
