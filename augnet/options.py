"""An estimator's settings as one table: each setting declared once, with its unit, meaning and source.

The table is a frozen-or-plain dataclass whose fields are made with `setting(...)`; the command line
(`--opt NAME=VALUE`), the generated reference page (`docs/options/*.md`) and validation all walk it, as
RTKLIB's `options.c` table feeds its config reader, writer and docs.
"""
from __future__ import annotations

import dataclasses
import math
import types
import typing
from dataclasses import MISSING, Field, field
from typing import Any

OPTION_META = "augnet.option"


class OptionError(ValueError):
    """A setting that cannot be accepted; the message names the field."""


def setting(default: Any = MISSING, *, doc: str, unit: str = "", source: str = "", choices=None,
            default_factory: Any = MISSING) -> Any:
    """A dataclass field that is one row of a settings table."""
    meta = {OPTION_META: {"doc": doc, "unit": unit, "source": source,
                          "choices": tuple(choices) if choices is not None else None}}
    if default_factory is not MISSING:
        return field(default_factory=default_factory, metadata=meta)
    return field(default=default, metadata=meta)


@dataclasses.dataclass(frozen=True)
class OptionRow:
    name: str
    default: Any
    unit: str
    doc: str
    source: str
    choices: tuple | None
    type: Any


def table(cls) -> list[OptionRow]:
    """The rows of a settings dataclass, in declaration order (fields made without `setting` are skipped)."""
    hints = typing.get_type_hints(cls)
    rows = []
    for f in dataclasses.fields(cls):
        meta = f.metadata.get(OPTION_META)
        if meta is None:
            continue
        rows.append(OptionRow(f.name, _default(f), meta["unit"], meta["doc"], meta["source"], meta["choices"],
                              hints.get(f.name, Any)))
    return rows


def _default(f: Field) -> Any:
    if f.default is not MISSING:
        return f.default
    if f.default_factory is not MISSING:
        return f.default_factory()
    return MISSING


def _convert(tp: Any, text: str, name: str) -> Any:
    """Parse `text` as type `tp` (bool, int, float, str, tuples of str, Optional of those)."""
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        if text.strip().lower() == "none" and type(None) in args:
            return None
        for a in (a for a in args if a is not type(None)):
            try:
                return _convert(a, text, name)
            except OptionError:
                continue
        raise OptionError(f"{name}: cannot read {text!r} as {tp}")
    if tp is bool:
        low = text.strip().lower()
        if low in ("1", "true", "yes", "on"):
            return True
        if low in ("0", "false", "no", "off"):
            return False
        raise OptionError(f"{name}: {text!r} is not a boolean (on/off, true/false, 1/0)")
    if tp in (int, float):
        try:
            value = tp(text)
        except ValueError:
            raise OptionError(f"{name}: {text!r} is not a{'n int' if tp is int else ' number'}") from None
        if tp is float and not math.isfinite(value):
            raise OptionError(f"{name}: {text!r} is not finite")
        return value
    if tp is str:
        return text
    if origin in (tuple, list, typing.Sequence) or tp in (tuple, list):
        items = tuple(s.strip() for s in text.split(",") if s.strip())
        return items if origin is not list else list(items)
    if typing.get_origin(tp) is None and isinstance(tp, type) and dataclasses.is_dataclass(tp):
        raise OptionError(f"{name}: a group of settings; set its fields one by one")
    return text


def with_assignments(options, assignments: list[str]):
    """A copy of `options` with `NAME=VALUE` assignments applied; an unknown name or bad value names the field."""
    rows = {r.name: r for r in table(type(options))}
    changes = {}
    for a in assignments:
        name, sep, text = a.partition("=")
        name = name.strip().replace("-", "_")
        if not sep:
            raise OptionError(f"{a!r}: expected NAME=VALUE")
        row = rows.get(name)
        if row is None:
            raise OptionError(f"{name}: no such setting (known: {', '.join(sorted(rows))})")
        changes[name] = _convert(row.type, text.strip(), name)
    new = dataclasses.replace(options, **changes)
    check(new)
    return new


def check(options) -> None:
    """Raise OptionError naming the first field whose value is outside its declared choices."""
    for row in table(type(options)):
        value = getattr(options, row.name)
        if row.choices is not None and value not in row.choices:
            raise OptionError(f"{row.name}: {value!r} is not one of {', '.join(map(repr, row.choices))}")


def markdown(cls, title: str) -> str:
    """The reference page of a settings table."""
    lines = [f"# {title}", "", f"Generated from `{cls.__module__}.{cls.__qualname__}`; do not edit by hand.", "",
             "| setting | default | unit | meaning | source |", "| --- | --- | --- | --- | --- |"]
    for r in table(cls):
        if r.default is MISSING:
            default = ""
        elif dataclasses.is_dataclass(r.default):
            default = f"{type(r.default).__name__}()"  # a group of settings at its own defaults
        else:
            default = repr(r.default)
        if r.choices:
            doc = f"{r.doc} (one of {', '.join(map(repr, r.choices))})"
        else:
            doc = r.doc
        cells = [f"`{r.name}`", f"`{default}`", r.unit, doc, r.source]
        lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return "\n".join(lines) + "\n"


# The generated reference pages: (page name under docs/options/, module, settings class, title).
PAGES = (
    ("rtk", "augnet.onboard.rtk", "RtkOptions", "Onboard RTK settings (`augnet rtk --opt NAME=VALUE`)"),
    ("centre", "augnet.centre.baseline_config", "BaselineConfig",
     "Network engine settings (`augnet vrs --opt NAME=VALUE`)"),
    ("vrs", "augnet.centre.vrs_admission", "AdmissionConfig",
     "VRS satellite admission (`augnet vrs` and `augnet up`: `--admission on|off`, `--admission-NAME VALUE`)"),
)


def page(name: str) -> str:
    """The generated text of docs/options/<name>.md."""
    import importlib

    for page_name, module, cls_name, title in PAGES:
        if page_name == name:
            return markdown(getattr(importlib.import_module(module), cls_name), title)
    raise KeyError(f"no options page {name!r} (known: {', '.join(p[0] for p in PAGES)})")


def write_pages(folder) -> list:
    """Write every page of PAGES into `folder` (docs/options); returns the paths written."""
    from pathlib import Path

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for name, *_ in PAGES:
        path = folder / f"{name}.md"
        path.write_text(page(name), encoding="utf-8")
        written.append(path)
    return written


if __name__ == "__main__":  # python -m augnet.options docs/options
    import sys

    for p in write_pages(sys.argv[1] if len(sys.argv) > 1 else "docs/options"):
        print(p)
