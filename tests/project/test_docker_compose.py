"""docker-compose.yml cannot be run here (no Docker engine): check its structure instead."""

from __future__ import annotations

import re
import tomllib
from urllib.parse import urlparse

import pytest
import yaml
from typer.testing import CliRunner

from tests.conftest import REPO_ROOT

REQUIRED_SERVICES = {"augnet", "postgres", "nats"}
AUGNET_SERVICES = {"augnet"}


@pytest.fixture(scope="module")
def compose() -> dict:
    return yaml.safe_load((REPO_ROOT / "docker-compose.yml").read_text())


def test_required_services_present(compose):
    assert REQUIRED_SERVICES <= set(compose["services"])


def test_depends_on_names_defined_services_without_cycles(compose):
    services = compose["services"]
    graph = {}
    for name, svc in services.items():
        deps = svc.get("depends_on", {})
        deps = list(deps) if isinstance(deps, (dict, list)) else []
        for dep in deps:
            assert dep in services, f"{name} depends on undefined service {dep}"
            if isinstance(svc["depends_on"], dict):
                cond = svc["depends_on"][dep]["condition"]
                assert cond in {"service_started", "service_healthy", "service_completed_successfully"}
                if cond == "service_healthy":
                    assert "healthcheck" in services[dep], f"{name} waits for {dep} health, which has no healthcheck"
        graph[name] = deps
    state: dict[str, int] = {}

    def visit(node, path):
        if state.get(node) == 1:
            raise AssertionError(f"dependency cycle: {' -> '.join(path + [node])}")
        if state.get(node) == 2:
            return
        state[node] = 1
        for dep in graph[node]:
            visit(dep, path + [node])
        state[node] = 2

    for node in graph:
        visit(node, [])


def test_published_ports_are_valid_and_unique(compose):
    seen = {}
    for name, svc in compose["services"].items():
        for spec in svc.get("ports", []):
            m = re.fullmatch(r"(\d+):(\d+)", str(spec))
            assert m, f"{name}: port spec {spec!r} is not HOST:CONTAINER"
            host = int(m.group(1))
            assert 0 < host < 65536 and 0 < int(m.group(2)) < 65536
            assert host not in seen, f"host port {host} published by {seen.get(host)} and {name}"
            seen[host] = name
    assert seen.get(2101) == "augnet" and seen.get(8000) == "augnet"


def test_augnet_services_build_this_repo_and_reach_store_and_bus(compose):
    services = compose["services"]
    pg_env = services["postgres"]["environment"]
    for name in AUGNET_SERVICES:
        svc = services[name]
        assert svc["build"] == ".", name
        env = svc["environment"]
        db = urlparse(env["AUGNET_DB_URL"])
        assert db.scheme.startswith("postgresql")
        assert db.hostname == "postgres" and db.port == 5432
        assert db.username == pg_env["POSTGRES_USER"] and db.password == pg_env["POSTGRES_PASSWORD"]
        assert db.path.lstrip("/") == pg_env["POSTGRES_DB"]
        bus = urlparse(env["AUGNET_BUS_URL"])
        assert bus.scheme == "nats" and bus.hostname == "nats" and bus.port == 4222
        assert "-js" in services["nats"]["command"], "the correction bus needs JetStream"


def test_dockerfile_copies_every_package_the_project_declares():
    dockerfile = (REPO_ROOT / "Dockerfile").read_text()
    pyproject = tomllib.loads((REPO_ROOT / "pyproject.toml").read_text())
    packages = [p.rstrip("*") for p in pyproject["tool"]["setuptools"]["packages"]["find"]["include"]]
    for pkg in packages:
        assert re.search(rf"^COPY {pkg} \./{pkg}$", dockerfile, re.M), f"Dockerfile does not copy {pkg}"
    assert 'ENTRYPOINT ["augnet"]' in dockerfile
    assert "augnet" in pyproject["project"]["scripts"]


@pytest.mark.parametrize("name", sorted(AUGNET_SERVICES))
def test_service_command_is_a_real_cli_command(compose, name, monkeypatch):
    """The service's exact arguments parse (an unknown option would fail before --help), and the store and
    bus URLs it is given in its environment reach the command."""
    from augnet import cli

    cli._mount()
    svc = compose["services"][name]
    for key, value in svc["environment"].items():
        monkeypatch.setenv(key, value)
    result = CliRunner().invoke(cli.app, [*svc["command"], "--help"])
    assert result.exit_code == 0, result.output
    assert "AUGNET_DB_URL" in result.output and "AUGNET_BUS_URL" in result.output
