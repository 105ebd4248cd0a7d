"""The live terminal view of `augnet up` (rich): stations, baselines, trains, correction age, alarms."""

from __future__ import annotations

import asyncio
import time

import numpy as np
from rich.console import Group
from rich.live import Live
from rich.panel import Panel
from rich.table import Table

from augnet.system.baseline_quality import FIXED_BASELINE_FRACTION
from augnet.system.live_state import CORRECTION_AGE_P99_EPOCHS

REFRESH_S = 1.0
ALARMS_SHOWN = 5  # the latest alarms raised
FIX_STYLE = {"fix": "bold green", "float": "yellow", "single": "red", "none": "dim"}


def render(system) -> Group:
    r = system.publisher.last_report
    head = Table.grid(padding=(0, 2))
    recent = system.publisher.correction_age_s[-CORRECTION_AGE_P99_EPOCHS:]
    ages = np.array(recent) if recent else np.array([])
    p99 = f"{np.percentile(ages, 99) * 1000:.0f} ms" if ages.size else "-"
    solve = system.centre.solve_ms_p99() if system.centre else None
    head.add_row(f"[b]augnet up[/b] {system.settings.scenario}",
                 f"console {system.console_url or '-'}",
                 f"caster :{system.caster.port if system.caster else '-'}",
                 f"up {time.time() - system.started:.0f} s")
    head.add_row(f"network epochs {system.centre.timings.epochs if system.centre else 0}",
                 f"correction age p99 {p99}", f"solve p99 {solve:.0f} ms" if solve else "solve -",
                 f"master {r.network.master if r else '-'}")

    st = Table(title="stations", expand=False)
    for c in ("station", "up", "km"):
        st.add_column(c)
    present = set(r.network.present) if r else set()
    excluded = system.centre.excluded_stations if system.centre else set()
    for code in sorted(system.centre.stations if system.centre else []):
        state = "[dim]disabled[/dim]" if code in excluded else ("[green]up[/green]" if code in present else "[red]down[/red]")
        km = system.station_km.get(code)
        st.add_row(code, state, f"{km:.1f}" if km is not None else "-")

    bl = Table(title="baselines")
    for c in ("baseline", "fixed"):
        bl.add_column(c)
    if r:
        for key, frac in sorted(r.network.fixed_fraction().items()):
            style = "green" if frac >= FIXED_BASELINE_FRACTION else "yellow" if frac > 0 else "red"
            bl.add_row(key, f"[{style}]{frac:.0%}[/{style}]")

    tr = Table(title="trains")
    for c in ("train", "state", "km", "track", "age s", "fix %", "TTFF s"):
        tr.add_column(c)
    for tid, t in sorted(system.trains.items()):
        out = t.last
        state = out.solution.status_name if out else "none"
        m = out.match if out else None
        n = max(1, t.stats.epochs)
        age = t.correction_age_s()
        tr.add_row(tid, f"[{FIX_STYLE[state]}]{state}[/{FIX_STYLE[state]}]",
                   f"{m.km:.3f}" if m is not None and m.track else "-", (m.track or "-") if m else "-",
                   f"{age:.1f}" if age is not None else "-", f"{100 * t.stats.by_status.get('fix', 0) / n:.0f}",
                   f"{t.stats.first_fix_s:.0f}" if t.stats.first_fix_s is not None else "-")

    al = Table(title="alarms (latest)")
    for c in ("kind", "subject", "severity"):
        al.add_column(c)
    for a in (system.alarms.log if system.alarms is not None else [])[-ALARMS_SHOWN:]:
        al.add_row(a["kind"], a["subject"], a["severity"])
    rbc = system.rbc.snapshot() if system.rbc else None
    foot = (f"RSSP-I link {'up' if rbc['link_up'] else 'down'}, RBC sections {rbc['sections']}, "
            f"RBC alarms {rbc['rbc_alarms']}" if rbc else "RSSP-I link off")
    grid = Table.grid(padding=(0, 2))
    grid.add_row(st, bl, tr)
    return Group(Panel(head), grid, al, foot, "[dim]Ctrl-C stops everything cleanly[/dim]")


async def run_view(system) -> None:
    with Live(render(system), refresh_per_second=2, transient=False) as live:
        while not system.stop_event.is_set():
            try:
                await asyncio.wait_for(system.stop_event.wait(), REFRESH_S)
            except asyncio.TimeoutError:
                pass
            try:
                live.update(render(system))
            except Exception:  # noqa: BLE001 - the view must never stop the system
                pass
