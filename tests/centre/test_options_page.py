"""The network engine's settings table: every row documented, and `augnet vrs --opt` reads it (the committed page
is checked with the others in tests/test_options.py)."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from augnet.centre.baseline_config import BaselineConfig
from augnet.options import OptionError, table, with_assignments


def test_every_setting_is_documented():
    rows = table(BaselineConfig)
    assert [r.name for r in rows] == list(BaselineConfig.__dataclass_fields__)
    assert all(r.doc for r in rows)


def test_assignments_reach_the_settings():
    cfg = with_assignments(BaselineConfig(), ["fix_ratio=3", "iono-shell-height-km=none", "iono_hints=off"])
    assert (cfg.fix_ratio, cfg.iono_shell_height_km, cfg.iono_hints) == (3.0, None, False)
    with pytest.raises(OptionError, match="fix_ratio"):
        with_assignments(BaselineConfig(), ["fix_ratio=x"])


def test_vrs_rejects_an_unknown_setting_by_name(tmp_path):
    from augnet.cli import _mount, app

    _mount()
    out = CliRunner().invoke(app, ["vrs", "--record", str(tmp_path), "--at", "0,0,0", "--out",
                                   str(tmp_path / "v.rnx"), "--opt", "no_such_setting=1"])
    assert out.exit_code == 2
    assert "no_such_setting" in out.stderr
