"""`augnet track ...`: track identification campaign on a line (railML or augnet-topology/1 JSON)."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from augnet.track.topology import TopologyError

app = typer.Typer(help="Track topology and track identification.", no_args_is_help=True, add_completion=False)


def _load(path: Path):
    from augnet.track.topology_file import import_railml, load_topology

    text = path.read_bytes()[:4096].lstrip()
    return import_railml(path) if text.startswith(b"<") else load_topology(path)


@app.command("campaign")
def campaign(line: Path = typer.Option(..., "--line", help="railML 2.x file or augnet-topology/1 JSON"),
             runs: int = typer.Option(16, "--runs", min=1, help="seeded runs (seeds 0..N-1)"),
             json_out: Path = typer.Option(None, "--json", help="also write the totals as JSON here"),
             error_scale: float = typer.Option(1.0, "--error-scale", help="stress: true error / reported sigma"),
             wrong_fix_bias: float = typer.Option(0.0, "--wrong-fix-bias",
                                                  help="stress: cross-track bias [m] of wrong fixes "
                                                       "(1 fixed spell in 5)")) -> None:
    """Seeded train runs through the line's switches with simulated solution errors; prints the report."""
    from augnet.track.campaign import run_campaign

    try:
        topo = _load(line)
    except (OSError, TopologyError) as exc:
        typer.echo(f"cannot use line {line}: {exc}", err=True)
        raise typer.Exit(2)
    try:
        rep = run_campaign(topo, range(runs), error_scale=error_scale, wrong_fix_bias_m=wrong_fix_bias)
    except ValueError as exc:
        typer.echo(f"cannot run the campaign: {exc}", err=True)
        raise typer.Exit(2)
    typer.echo(rep.text())
    if json_out is not None:
        json_out.write_text(json.dumps(rep.totals(), indent=1))
    if rep.totals()["wrong"]:
        raise typer.Exit(1)
