"""`augnet scenario run SCENARIO --out DIR [--duration S] [--warm-up S]`: the whole chain faster than real time,
a progress bar while it runs, then the targets as a table; report.json, epochs.csv and the PNG plots in DIR.
`augnet scenario campaign [CAMPAIGN] --out DIR`: a fault-injection matrix of scenarios x seeds, one report
(augnet/scenario/campaign.py)."""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer
from rich.console import Console
from rich.table import Table

from stations.scenario import ScenarioError

app = typer.Typer(help="Run a scenario end to end, faster than real time: report.json + plots.",
                  no_args_is_help=True, add_completion=False)


def _fmt(v) -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return str(v)
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def targets_table(report) -> Table:
    """One row per target (report.json's `targets` says what each one is)."""
    table = Table(title=f"{report.scenario['name']}: targets (report.json: 'targets')", show_lines=False)
    for col in ("target", "required", "measured", "unit", "result"):
        table.add_column(col, no_wrap=True)
    for t in report.targets:
        result = {True: "[green]pass[/green]", False: "[red]FAIL[/red]", None: "[yellow]n/a[/yellow]"}[t["pass"]]
        table.add_row(t["id"], t["target"], _fmt(t["measured"]), t["unit"], result)
    return table


@app.command("run")
def run_cmd(scenario: str = typer.Argument(..., help="built-in name (demo, baseline-10km, network-70km, "
                                                      "iono-storm) or a scenario YAML file"),
            out: Path = typer.Option(..., "--out", help="output folder (created)"),
            duration: Optional[float] = typer.Option(None, "--duration", help="simulate only the first S seconds"),
            alert_limit: Optional[float] = typer.Option(None, "--alert-limit",
                                                        help="horizontal alert limit for the Stanford plot [m]"),
            warm_up: Optional[float] = typer.Option(
                None, "--warm-up", help="seconds the stations and the centre run before the trains' time 0 "
                                        "(default 300 with trains, 0 without; 0: a cold centre)"),
            no_plots: bool = typer.Option(False, "--no-plots", help="report.json and epochs.csv only"),
            strict: bool = typer.Option(False, "--strict", help="exit 1 when a target is not met"),
            quiet: bool = typer.Option(False, "--quiet", help="no progress bar")) -> None:
    """Simulate SCENARIO (stations -> centre -> VRS -> onboard units) and compare every figure with the truth."""
    from augnet.scenario.runner import run

    console = Console()
    try:
        rep = run(scenario, out, duration_s=duration, progress=not quiet, plots=not no_plots,
                  alert_limit_m=alert_limit, warm_up_s=warm_up)
    except ScenarioError as exc:
        console.print(f"[red]error:[/red] {exc}")
        raise typer.Exit(2) from None
    console.print(targets_table(rep))
    r = rep.run
    warm = f" after a {_fmt(r['warm_up_s'])} s warm-up of the stations and the centre" if r["warm_up_s"] else ""
    console.print(f"{r['epochs']} epochs{warm} in {r['wall_s']:.1f} s ({_fmt(r['real_time_factor'])}x real time); "
                  f"wrote {', '.join(rep.files)} to {out}")
    if strict and not rep.passed:
        raise typer.Exit(1)


@app.command("campaign")
def campaign_cmd(campaign: str = typer.Argument("issue15", help="built-in campaign name (issue15) or a campaign "
                                                                "YAML file (augnet/scenario/campaigns/)"),
                 out: Path = typer.Option(..., "--out", help="output folder (created)"),
                 no_plots: bool = typer.Option(False, "--no-plots", help="campaign.json and campaign.md only"),
                 strict: bool = typer.Option(False, "--strict", help="exit 1 when a must-show check fails")) -> None:
    """Run every scenario x seed pair of a fault-injection campaign; one report (markdown + JSON + Stanford plots)."""
    from augnet.scenario.campaign import run_campaign

    console = Console()

    def progress(res) -> None:
        wm = [per["weighted_median"] for per in res.figures.values()]
        console.print(f"{res.pair}: {res.wall_s:.0f} s; weighted median available "
                      f"{sum(f['available'] for f in wm)}/{sum(f['epochs'] for f in wm)}, "
                      f"HMI {sum(f['hmi'] for f in wm)}; faults {len(res.faults)}")

    try:
        doc = run_campaign(campaign, out, plots=not no_plots, on_pair=progress)
    except ScenarioError as exc:
        console.print(f"[red]error:[/red] {exc}")
        raise typer.Exit(2) from None
    table = Table(title=f"campaign {doc['campaign']['name']}: must show ({out / 'campaign.md'})")
    for col in ("check", "target", "measured", "result"):
        table.add_column(col)
    for c in doc["summary"]["checks"]:
        table.add_row(c["what"], c["target"], _fmt(c["measured"]),
                      "[green]pass[/green]" if c["pass"] else "[red]FAIL[/red]")
    console.print(table)
    console.print(f"wrote {', '.join(doc['files'])} to {out}")
    if strict and not all(c["pass"] for c in doc["summary"]["checks"]):
        raise typer.Exit(1)


@app.command("track-id")
def track_id_cmd(scenario: str = typer.Argument("alpha-beta", help="a scenario with a layout"),
                 track_map: Optional[List[Path]] = typer.Option(None, "--map", help="augnet-topology/1 map the "
                                                                "identifier uses (repeatable; default: the as-built "
                                                                "truth exported by the simulator)"),
                 seeds: Optional[str] = typer.Option(None, "--seeds", help="a campaign: seeds FROM-TO (inclusive)"),
                 vary: bool = typer.Option(False, "--vary", help="campaign: move each train's start back 0-30 m "
                                                                 "and draw its speed 80-120 km/h per seed"),
                 warm_up: float = typer.Option(60.0, "--warm-up", help="seconds the centre runs before the trains"),
                 json_out: Optional[Path] = typer.Option(None, "--json", help="also write the totals here")) -> None:
    """Track identification on the onboard solutions of the full chain, per switch passage against truth."""
    import json

    from augnet.scenario.runner import load
    from augnet.scenario.track_identification import campaign, merged
    from augnet.track.topology import Topology
    from augnet.track.topology_file import load_topology
    from stations.layout import Layout

    try:
        sc = load(scenario)
        if sc.layout is None:
            raise ScenarioError(f"scenario {sc.name} has no layout")
        layout = Layout.load(sc.layout.file)
        if seeds:
            a, _, b = seeds.partition("-")
            seed_list = list(range(int(a), int(b or a) + 1))
        else:
            seed_list = [sc.seed]
    except (ScenarioError, ValueError) as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None
    maps = {}
    for p in track_map or []:
        t = load_topology(p)
        maps[f"{t.name} [{p}]"] = t
    if not maps:
        t = Topology.from_dict(layout.truth_topology_dict())
        maps[t.name] = t

    def progress(seed, name, res):
        t = res.totals()
        typer.echo(f"seed {seed} {name}: decided {t['decided']} / {t['epochs']}, wrong {t['wrong']}, unknown "
                   f"{t['unknown']}, facing {t['facing_decided']} / {t['facing_switches']}, after the frog "
                   f"{t['after_frog_m']}")

    results = campaign(sc, seed_list, maps, vary=vary, warm_up_s=warm_up, progress=progress)
    totals, wrong = [], 0
    for name, rs in results.items():
        m = merged(rs)
        acc = maps[name].accuracy
        typer.echo(f"== map: {name}" + (f" (accuracy {acc})" if acc else ""))
        typer.echo(m.text())
        totals.append({"map": name, "seeds": seed_list, "vary": vary, **m.totals()})
        wrong += m.wrong
    if json_out is not None:
        json_out.write_text(json.dumps(totals, indent=1))
    if wrong:
        raise typer.Exit(1)


@app.command("integrity")
def integrity_cmd(scenario: str = typer.Argument("alpha-beta-integrity", help="a layout scenario whose trains "
                                                                          "have rear antennas"),
                  seeds: str = typer.Option("16-25", "--seeds", help="seeds FROM-TO (inclusive)"),
                  split: bool = typer.Option(False, "--split", help="one train_split per train and run"),
                  window: str = typer.Option("20-30", "--window", help="split times drawn in FROM-TO [s]"),
                  decel: Optional[List[float]] = typer.Option(None, "--decel", help="rear deceleration(s) "
                                                                                    "[m/s^2], taken in turn"),
                  train: Optional[List[str]] = typer.Option(None, "--train", help="split only these trains"),
                  warm_up: float = typer.Option(60.0, "--warm-up", help="seconds the centre runs before the trains"),
                  json_out: Optional[Path] = typer.Option(None, "--json", help="also write the totals here")) -> None:
    """Train integrity from two antennas in the full chain: false alarms (fault-free) or split detection times."""
    import json

    from augnet.scenario.runner import load
    from augnet.scenario.train_integrity import SPLIT_DECEL_M_S2, run, totals

    try:
        sc = load(scenario)
        a, _, b = seeds.partition("-")
        seed_list = list(range(int(a), int(b or a) + 1))
        w0, _, w1 = window.partition("-")
        win = (float(w0), float(w1 or w0))
    except (ScenarioError, ValueError) as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None

    def progress(seed, res):
        for r in res:
            typer.echo(f"seed {seed} {r.train}: confirmed {r.confirmed} / {r.epochs}, lost {r.lost}, split "
                       f"{r.split_at_s:g} s ({r.split_decel_m_s2:g} m/s^2), lost at {r.lost_at_s:g} s, gap at the "
                       f"alarm {r.gap_at_alarm_m:.2f} m, fault-free |error| max {r.max_error_fault_free_m:.3f} m "
                       f"({r.max_ratio_fault_free:.2f} of the bound)")

    args = {"window_s": win, "decels_m_s2": tuple(decel) if decel else SPLIT_DECEL_M_S2, "trains": train or None}
    runs = run(sc, seed_list, split=split, warm_up_s=warm_up, progress=progress, **(args if split else {}))
    tot = totals(runs)
    typer.echo(json.dumps(tot))
    if json_out is not None:
        json_out.write_text(json.dumps(tot, indent=1))
    if tot["false_alarms"] or tot["missed"]:
        raise typer.Exit(1)
