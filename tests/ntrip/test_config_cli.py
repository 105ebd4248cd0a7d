"""Configuration files (TOML and YAML), password hashing, and the command line."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from augwire.passwords import hash_password, verify_password
from ntrip_caster.auth import Authenticator, User
from ntrip_caster.cli import app
from ntrip_caster.config import ConfigError, load_config

from .helpers import open_client, open_v1_source, read_all

FAST_HASH = hash_password("pw", log2_n=10)

TOML = f"""
[caster]
host = "127.0.0.1"
port = 0
identifier = "Line 7"
country = "CHN"

[limits]
max_clients = 50
request_head_timeout_s = 2.5

[users.train1]
password_hash = "{FAST_HASH}"
groups = ["trains"]

[users.st1]
password_hash = "{FAST_HASH}"
groups = ["stations"]

[[mountpoints]]
name = "BASE01"
read = ["trains"]
write = ["stations"]
latitude = 31.2
longitude = 121.4
format_details = "1005(10),1077(1)"

[[mountpoints]]
name = "NEAR"
kind = "nearest"
read = ["*"]
"""

YAML = f"""
caster: {{host: 127.0.0.1, port: 0}}
users:
  train1: {{password_hash: "{FAST_HASH}", groups: [trains]}}
mountpoints:
  - {{name: BASE01, read: [trains], write: [trains], latitude: 31.2, longitude: 121.4}}
"""


def test_toml_and_yaml(tmp_path):
    p = tmp_path / "c.toml"
    p.write_text(TOML)
    cfg = load_config(p)
    assert cfg.limits.max_clients == 50 and cfg.limits.request_head_timeout_s == 2.5
    assert cfg.users["train1"].groups == frozenset({"trains"})
    base, near = cfg.mounts
    rec = base.str_record()
    assert (rec.mountpoint, rec.latitude, rec.authentication, rec.nmea) == ("BASE01", 31.2, "B", 0)
    assert near.str_record().nmea == 1 and near.str_record().authentication == "N"
    y = tmp_path / "c.yaml"
    y.write_text(YAML)
    assert load_config(y).mounts[0].write == frozenset({"trains"})


@pytest.mark.parametrize("text,needle", [
    ("[caster]\nbogus = 1\n", "unknown keys"),
    ("[limits]\nmax_clients = -1\n", "non-negative"),
    ("[limits]\nnope = 1\n", "unknown keys"),
    ("[users.a]\npassword_hash = \"plain\"\n", "scrypt"),
    ("[[mountpoints]]\nname = \"V\"\nkind = \"vrs\"\n", "factory"),
    ("[[mountpoints]]\nname = \"V\"\nkind = \"weird\"\n", "kind"),
    ("[[mountpoints]]\nname = \"A\"\n[[mountpoints]]\nname = \"A\"\n", "twice"),
    ("[[mountpoints]]\nname = \"A\"\ncolour = 1\n", "unknown keys"),
    ("this is not toml", "c.toml"),
])
def test_config_errors_are_clear(tmp_path, text, needle):
    p = tmp_path / "c.toml"
    p.write_text(text)
    with pytest.raises(ConfigError, match=needle):
        load_config(p)


def test_scrypt_hashes():
    h = hash_password("s3cret", log2_n=10)
    assert h.startswith("scrypt$10$8$1$") and "s3cret" not in h
    assert verify_password("s3cret", h) and not verify_password("s3cre", h)
    assert hash_password("s3cret", log2_n=10) != h  # salted
    assert not verify_password("x", "scrypt$bad") and not verify_password("x", "md5$1$2$3$4$5")
    auth = Authenticator({"u": User("u", h, frozenset({"g"}))})
    assert auth.check("u", "s3cret") == "u" and auth.checks == 1
    assert auth.cached_user("u", "s3cret") == "u" and auth.cached_user("u", "other") is None
    assert auth.check("u", "wrong") is None and auth.check("ghost", "x") is None
    assert auth.allowed("u", frozenset({"g"})) and not auth.allowed("u", frozenset({"h"}))
    assert auth.allowed(None, frozenset({"*"})) and not auth.allowed(None, frozenset({"g"}))


def test_cli_hash_password_check_and_sourcetable(tmp_path):
    runner = CliRunner()
    out = runner.invoke(app, ["hash-password", "--password", "abc"])
    assert out.exit_code == 0 and verify_password("abc", out.stdout.strip())
    p = tmp_path / "c.toml"
    p.write_text(TOML)
    out = runner.invoke(app, ["check", "-c", str(p)])
    assert json.loads(out.stdout)["mountpoints"] == {"BASE01": "source", "NEAR": "nearest"}
    out = runner.invoke(app, ["sourcetable", "-c", str(p)])
    assert "STR;BASE01;;RTCM 3.3;1005(10),1077(1);" in out.stdout
    assert out.stdout.replace("\r\n", "\n").endswith("ENDSOURCETABLE\n")
    bad = tmp_path / "bad.toml"
    bad.write_text("[caster]\nbogus = 1\n")
    out = runner.invoke(app, ["check", "-c", str(bad)])
    assert out.exit_code == 2 and "unknown keys" in out.stderr


@pytest.mark.slow
def test_serve_subprocess_stats_file_and_sigterm(tmp_path):
    p = tmp_path / "c.toml"
    stats = tmp_path / "stats.json"
    p.write_text(TOML.replace('country = "CHN"', f'country = "CHN"\nstats_path = "{stats}"\n'
                                                 'stats_interval_s = 0.2'))
    ready = tmp_path / "port"
    proc = subprocess.Popen([sys.executable, "-m", "ntrip_caster.cli", "serve", "-c", str(p),
                             "--ready-file", str(ready), "--log-level", "WARNING"],
                            stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 20
        while not (ready.exists() and ready.read_text()):
            assert proc.poll() is None and time.monotonic() < deadline
            time.sleep(0.05)
        port = int(ready.read_text())
        src = open_v1_source(port, "BASE01", password="pw")  # noqa: F841 - keeps BASE01 live
        c, head = open_client(port, "BASE01", user="train1", password="pw")
        assert head == b"ICY 200 OK\r\n"
        deadline = time.monotonic() + 10
        while True:
            snap = json.loads(stats.read_text()) if stats.exists() else {}
            if snap.get("clients_now") == 1:
                break
            assert time.monotonic() < deadline
            time.sleep(0.1)
        assert snap["mounts"]["BASE01"]["source"]["user"] == "st1"
        assert snap["clients"][0]["user"] == "train1"
        os.kill(proc.pid, signal.SIGTERM)
        assert proc.wait(timeout=10) == 0
        assert read_all(c, timeout=5) == b""  # closed cleanly by the shutdown
    finally:
        if proc.poll() is None:
            proc.kill()


def test_example_config_is_valid():
    example = Path(__file__).resolve().parents[2] / "ntrip_caster" / "example-caster.toml"
    cfg = load_config(example)
    assert [m.name for m in cfg.mounts] == ["BASE01", "NEAREST"]
    assert verify_password("change-me", cfg.users["train0001"].password_hash)
