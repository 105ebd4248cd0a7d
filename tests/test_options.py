"""Settings tables: one declaration feeds parsing, validation and the reference page."""
from dataclasses import dataclass

import pytest

from augnet.options import OptionError, check, markdown, setting, table, with_assignments


@dataclass(frozen=True)
class _Demo:
    ratio: float = setting(3.0, doc="ratio-test threshold", source="RTKLIB pos2-arthres")
    tries: int = setting(8, doc="searches at most")
    hold: bool = setting(True, doc="fix and hold")
    mode: str = setting("auto", doc="ionosphere model", choices=("auto", "off"))
    sigma_m: float | None = setting(None, doc="prior sigma", unit="m")
    systems: tuple[str, ...] = setting(("G", "E"), doc="constellations")


def test_assignments_are_typed_and_validated():
    o = with_assignments(_Demo(), ["ratio=2.5", "tries=3", "hold=off", "mode=off", "sigma-m=0.02", "systems=G"])
    assert (o.ratio, o.tries, o.hold, o.mode, o.sigma_m, o.systems) == (2.5, 3, False, "off", 0.02, ("G",))
    assert with_assignments(o, ["sigma_m=none"]).sigma_m is None


@pytest.mark.parametrize("bad, field", [("ratio=x", "ratio"), ("tries=1.5", "tries"), ("hold=maybe", "hold"),
                                        ("mode=on", "mode"), ("nope=1", "nope"), ("ratio=nan", "ratio")])
def test_bad_values_name_the_field(bad, field):
    with pytest.raises(OptionError, match=field):
        with_assignments(_Demo(), [bad])


def test_reference_page_lists_every_row():
    page = markdown(_Demo, "Demo settings")
    assert [r.name for r in table(_Demo)] == ["ratio", "tries", "hold", "mode", "sigma_m", "systems"]
    assert all(f"`{r.name}`" in page for r in table(_Demo)) and "RTKLIB pos2-arthres" in page
    check(_Demo())


def test_the_committed_options_pages_are_the_generated_ones():
    from pathlib import Path

    from augnet.options import PAGES, page

    docs = Path(__file__).resolve().parents[1] / "docs" / "options"
    for name, *_ in PAGES:
        assert (docs / f"{name}.md").read_text(encoding="utf-8") == page(name), (
            f"docs/options/{name}.md is stale: regenerate with `python -m augnet.options docs/options`")
