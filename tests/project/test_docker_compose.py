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


NATS_NODES = ("nats", "nats-2", "nats-3")  # issue 17: 3 JetStream nodes for R3 streams


def test_every_service_has_a_healthcheck_and_restart_policy(compose):
    for name, svc in compose["services"].items():
        assert svc.get("restart") in {"always", "unless-stopped", "on-failure"}, name
        assert svc.get("healthcheck", {}).get("test"), f"{name} has no healthcheck"


def test_three_nats_nodes_form_one_jetstream_cluster(compose):
    services = compose["services"]
    for name in NATS_NODES:
        cmd = services[name]["command"]
        assert "-js" in cmd and cmd[cmd.index("--name") + 1] == name
        routes = {urlparse(u).hostname for u in cmd[cmd.index("--routes") + 1].split(",")}
        assert routes == set(NATS_NODES) - {name}, f"{name} routes to {routes}"
        assert cmd[cmd.index("--cluster_name") + 1] == "augnet"
    data = [services[n]["volumes"][0].split(":")[0] for n in NATS_NODES]
    assert len(set(data)) == 3, "each JetStream node needs its own store"


def test_national_layout_two_centres_per_region_three_casters(compose):
    services = compose["services"]
    national = {n: s for n, s in services.items() if "national" in s.get("profiles", [])}
    regions: dict[str, int] = {}
    for svc in national.values():
        if svc["command"][:2] == ["node", "centre"]:
            region = svc["command"][svc["command"].index("--region") + 1]
            regions[region] = regions.get(region, 0) + 1
    assert len(regions) >= 2 and all(n == 2 for n in regions.values()), regions
    casters = [s for s in national.values() if s["command"][:2] == ["node", "caster"]]
    assert len(casters) == 3
    for name, svc in national.items():
        assert svc["build"] == "." and set(svc["depends_on"]) >= {"postgres", *NATS_NODES}, name


def test_single_node_services_run_without_a_profile(compose):
    """`docker compose up` without --profile keeps the runnable one-process system."""
    default = {n for n, s in compose["services"].items() if not s.get("profiles")}
    assert default == REQUIRED_SERVICES | {"nats-2", "nats-3"}
