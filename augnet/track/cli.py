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


@app.command("build-map")
def build_map_cmd(layout: Path = typer.Option(..., "--layout", help="layout description (augnet-topology/1 or railML)"),
                  survey: Path = typer.Option(..., "--survey", help="survey record (augnet-survey/1) to build from"),
                  verify_with: Path = typer.Option(..., "--verify", help="an independent survey record to verify"),
                  out: Path = typer.Option(..., "--out", help="the built map (augnet-topology/1, with its accuracy)")) -> None:
    """A track map from a survey run: topology from the layout, geometry fitted to the survey, verified."""
    from augnet.track.survey_map import build_map, verify
    from augnet.track.topology_file import save_topology

    try:
        desc = _load(layout)
        built = build_map(desc, json.loads(survey.read_text()))
        acc = verify(built, json.loads(verify_with.read_text()))
    except (OSError, ValueError) as exc:
        typer.echo(f"cannot build the map: {exc}", err=True)
        raise typer.Exit(2)
    save_topology(built.topology, out)
    for f in built.fits.values():
        gaps = ", ".join(f"{a:.0f}-{b:.0f} m" for a, b in f.gaps_m)
        typer.echo(f"{f.edge:>8}: {f.points} points, {f.outliers} outliers, {f.vertices} vertices, "
                   f"rms {100 * f.rms_h_m:.2f} cm{', gaps ' + gaps if gaps else ''}")
    typer.echo(f"verified against {acc['verified_against']}: 95 % {100 * acc['horizontal_95_m']:.1f} cm, "
               f"max {100 * acc['horizontal_max_m']:.1f} cm ({acc['points']} points, {acc['outliers_dropped']} "
               f"outliers dropped) -> {out}")
