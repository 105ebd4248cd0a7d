"""The run's PNG plots (matplotlib's Agg canvas, no pyplot state, no display needed):

- error_over_time.png  per train: horizontal and vertical error against the truth, epoch by epoch, coloured
                       by solution status, with the protection levels and the epochs without sky shaded;
- stanford.png         horizontal error against the horizontal protection level, every epoch of every train
                       with a position, as a 2-D histogram with the diagonal and the alert limit: normal
                       operation (error < HPL < AL), misleading information (HPL < error), hazardously
                       misleading (HPL < AL < error), system unavailable (HPL > AL) (the Stanford plot of
                       WAAS integrity analysis, Tsai / Enge, Stanford GPS Laboratory);
- network_map.png      stations, check points, baselines coloured by their mean fixed fraction, the line,
                       tunnels and cuttings, the trains' true paths and their estimated positions.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import LogNorm
from matplotlib.figure import Figure

from augnet.gnss.geometry import ecef_to_enu, geodetic_deg_to_ecef
from augnet.onboard.rtk import Status
from augnet.scenario.metrics import runs

ERROR_OVER_TIME_PNG = "error_over_time.png"
STANFORD_PNG = "stanford.png"
STANFORD_ALONG_PNG = "stanford_along_{method}.png"  # one per along-track method (decision 0201)
NETWORK_MAP_PNG = "network_map.png"
DPI = 110
STATUS_COLOURS = {Status.FIX: "tab:green", Status.FLOAT: "tab:orange", Status.SINGLE: "tab:red",
                  Status.NONE: "tab:gray"}
PLOT_FLOOR_M = 1e-4  # errors below this are drawn at it (log axes)
STANFORD_RANGE_M = (1e-3, 1e2)
STANFORD_BINS = 60


def _save(fig: Figure, path: Path) -> None:
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=DPI)


def error_over_time(series: dict, path: Path, scenario_name: str) -> None:
    n = max(len(series), 1)
    fig = Figure(figsize=(11, 3.2 * n), layout="constrained")
    axes = fig.subplots(n, 1, squeeze=False)[:, 0]
    for ax, (tid, s) in zip(axes, series.items()):
        t = s["t"]
        for a, b in runs(~s["sky"]):
            ax.axvspan(t[a] - 0.5, t[min(b, len(t)) - 1] + 0.5, color="0.85", lw=0, zorder=0)
        for st, colour in STATUS_COLOURS.items():
            m = (s["status"] == st) & np.isfinite(s["h"])
            if m.any():
                ax.scatter(t[m], np.maximum(s["h"][m], PLOT_FLOOR_M), s=6, color=colour, label=f"H error ({st.name.lower()})")
        ax.plot(t, np.maximum(s["v"], PLOT_FLOOR_M), lw=0.6, color="tab:blue", alpha=0.6, label="V error")  # gaps stay gaps
        ax.plot(t, np.where(np.isfinite(s["hpl"]), s["hpl"], np.nan), lw=0.9, color="k", ls="--", label="HPL")
        ax.plot(t, np.where(np.isfinite(s["vpl"]), s["vpl"], np.nan), lw=0.7, color="tab:purple", ls=":", label="VPL")
        ax.axhline(0.02, color="tab:green", lw=0.6, ls="-.", label="2 cm")
        ax.set_yscale("log")
        ax.set_ylim(PLOT_FLOOR_M, 100.0)
        ax.set_xlim(t[0] if len(t) else 0, t[-1] if len(t) else 1)
        ax.set_ylabel("metres")
        ax.set_title(f"{scenario_name}: train {tid} (grey: no satellites tracked)", fontsize=10)
        ax.grid(True, which="major", alpha=0.3)
        ax.legend(loc="upper right", fontsize=7, ncol=4)
    axes[-1].set_xlabel("seconds since scenario start")
    _save(fig, path)


def stanford(series: dict, path: Path, alert_limit_m: float, title: str, quantity: str = "horizontal") -> dict:
    """Returns the region counts drawn. `series`: per train {"h": |error|, "hpl": protection level}."""
    h = np.concatenate([s["h"] for s in series.values()]) if series else np.zeros(0)
    pl = np.concatenate([s["hpl"] for s in series.values()]) if series else np.zeros(0)
    ok = np.isfinite(h) & np.isfinite(pl)
    h, pl = np.maximum(h[ok], STANFORD_RANGE_M[0]), np.maximum(pl[ok], STANFORD_RANGE_M[0])
    lo, hi = STANFORD_RANGE_M
    al = alert_limit_m
    counts = {"normal": int(((h <= pl) & (pl <= al)).sum()),
              "misleading": int(((h > pl) & (h <= al)).sum()),
              "hazardously_misleading": int(((h > pl) & (h > al) & (pl <= al)).sum()),
              "unavailable": int((pl > al).sum())}
    fig = Figure(figsize=(7.5, 6.5), layout="constrained")
    ax = fig.subplots()
    # regions first (behind the histogram)
    ax.fill_between([lo, hi], [lo, hi], lo, color="#f7c6c6", zorder=0)  # below the diagonal: error > PL
    ax.fill_between([al, hi], [al, al], lo, color="#e88", zorder=0)  # error > AL with PL < AL: HMI
    ax.fill_between([lo, hi], [hi, hi], al, color="0.88", zorder=0)  # PL > AL: unavailable
    bins = np.logspace(np.log10(lo), np.log10(hi), STANFORD_BINS + 1)
    if h.size:
        H, xe, ye = np.histogram2d(h, pl, bins=[bins, bins])
        mesh = ax.pcolormesh(xe, ye, np.ma.masked_equal(H.T, 0), norm=LogNorm(vmin=1, vmax=max(H.max(), 1)),
                             cmap="viridis", zorder=2)
        fig.colorbar(mesh, ax=ax, label="epochs")
    ax.plot([lo, hi], [lo, hi], color="k", lw=0.8, zorder=3)
    ax.axvline(al, color="k", lw=0.8, ls="--", zorder=3)
    ax.axhline(al, color="k", lw=0.8, ls="--", zorder=3)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlim(lo, hi)
    ax.set_ylim(lo, hi)
    ax.set_xlabel(f"{quantity} position error [m]")
    ax.set_ylabel(f"{quantity} protection level [m]")
    ax.set_title(f"{title}: {int(ok.sum())} epochs, alert limit {al:g} m", fontsize=10)
    kw = {"fontsize": 8, "zorder": 4, "ha": "center"}
    ax.text(np.sqrt(lo * al) / 3, np.sqrt(al * lo) * 3, f"normal operation\n{counts['normal']}", **kw)
    ax.text(np.sqrt(lo * al) * 3, np.sqrt(lo * al) / 3, f"misleading\ninformation\n{counts['misleading']}", **kw)
    ax.text(np.sqrt(al * hi), np.sqrt(lo * al), f"hazardously\nmisleading\n{counts['hazardously_misleading']}", **kw)
    ax.text(np.sqrt(lo * hi), np.sqrt(al * hi), f"system unavailable\n{counts['unavailable']}", **kw)
    _save(fig, path)
    return counts


def network_map(log, report, path: Path) -> None:
    names = list(log.stations)
    xyz = np.array([log.stations[n] for n in names])
    origin = xyz.mean(axis=0)

    def en_km(p):
        p = np.atleast_2d(p)
        return ecef_to_enu(p - origin, origin)[:, :2] / 1000.0

    def llh_km(llh):
        llh = np.asarray(llh, float)
        return en_km(geodetic_deg_to_ecef(llh[:, 0], llh[:, 1], llh[:, 2]))

    fig = Figure(figsize=(10, 7.5), layout="constrained")
    ax = fig.subplots()
    if log.line_llh is not None:
        line = llh_km(log.line_llh)
        ax.plot(line[:, 0], line[:, 1], color="0.55", lw=1.2, label="line", zorder=1)
        for b in log.blockages:
            p = llh_km(b["llh"])
            style = {"tunnel": ("k", 5), "cutting": ("saddlebrown", 4)}.get(b["kind"], ("0.3", 3))
            ax.plot(p[:, 0], p[:, 1], color=style[0], lw=style[1], solid_capstyle="butt", zorder=2)
            ax.annotate(b["kind"], p[len(p) // 2], textcoords="offset points", xytext=(6, -10), fontsize=7)
    pos = en_km(xyz)
    cmap = _cmap()
    for name, b in report.baselines.items():
        a, c = names.index(b["station_a"]), names.index(b["station_b"])
        ff = b["fixed_fraction_mean"]
        colour = cmap(ff) if ff is not None else "0.6"
        ax.plot(pos[[a, c], 0], pos[[a, c], 1], color=colour, lw=3, alpha=0.9, zorder=3)
        mid = 0.5 * (pos[a] + pos[c])
        wrong = b["wrong_fixes"]
        ax.annotate(f"{b['length_km']:.0f} km" + (f", {wrong} wrong" if wrong else ""), mid, fontsize=7,
                    color="0.2", ha="center", zorder=6)
    sm = _scalar_mappable(cmap)
    fig.colorbar(sm, ax=ax, label="baseline: mean fixed fraction after its first fix")
    ax.scatter(pos[:, 0], pos[:, 1], marker="^", s=90, color="navy", zorder=5, label="reference station")
    for n, p in zip(names, pos):
        ax.annotate(n, p, textcoords="offset points", xytext=(6, 6), fontsize=8, zorder=6)
    if log.check_points:
        cp = en_km(np.array(list(log.check_points.values())))
        ax.scatter(cp[:, 0], cp[:, 1], marker="D", s=50, color="purple", zorder=5, label="check point")
    colours = ["tab:red", "tab:blue", "tab:green", "tab:purple", "tab:orange", "tab:cyan"]
    for k, (tid, tl) in enumerate(log.trains.items()):
        truth = en_km(np.array(tl.truth_position))
        ax.plot(truth[:, 0], truth[:, 1], color=colours[k % len(colours)], lw=2.5, zorder=4,
                label=f"{tid} (truth path)")
        ax.annotate(tid, truth[0], textcoords="offset points", xytext=(-10, 8), fontsize=8,
                    color=colours[k % len(colours)], zorder=6)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("east [km]")
    ax.set_ylabel("north [km]")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    ax.set_title(f"{log.scenario.name}: network, line and trains", fontsize=10)
    _save(fig, path)


def _cmap():
    from matplotlib import colormaps

    return colormaps["RdYlGn"]


def _scalar_mappable(cmap):
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    return ScalarMappable(norm=Normalize(0.0, 1.0), cmap=cmap)


def along_track_series(log, method: str) -> dict:
    """Per train: |fused along-track position - truth| and the method's PL, every epoch (NaN/inf: none)."""
    out = {}
    for tid, tl in log.trains.items():
        fused = tl.fused.get(method, [])
        if len(fused) != len(tl.truth_km):
            continue
        x = np.array([f.position_m for f in fused], float)
        out[tid] = {"h": np.abs(x - np.array(tl.truth_km, float) * 1000.0),
                    "hpl": np.array([f.pl_m for f in fused], float)}
    return out


def write_all(log, report, out_dir: Path) -> list[str]:
    from augnet.onboard.along_track_fusion import ALONG_TRACK_ALERT_LIMIT_M, METHODS

    out = Path(out_dir)
    error_over_time(log.series, out / ERROR_OVER_TIME_PNG, log.scenario.name)
    stanford(log.series, out / STANFORD_PNG, report.definitions["alert_limit_m"], log.scenario.name)
    network_map(log, report, out / NETWORK_MAP_PNG)
    files = [ERROR_OVER_TIME_PNG, STANFORD_PNG, NETWORK_MAP_PNG]
    if any(tl.fused for tl in log.trains.values()):
        for method in METHODS:
            name = STANFORD_ALONG_PNG.format(method=method)
            stanford(along_track_series(log, method), out / name, ALONG_TRACK_ALERT_LIMIT_M,
                     f"{log.scenario.name} {method}", quantity="along-track")
            files.append(name)
    return files
