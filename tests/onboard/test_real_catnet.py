"""Must-show on real 20 km data: `augnet rtk` UPC1 (rover, 1 Hz) against GARR (base, 30 s, 19.7 km), GPS L1+L2,
side by side with RTKLIB 2.4.3's rnx2rtkp on the same span, base coordinates and settings.

Truth: UPC1 at 4789013.1051, 176610.1545, 4195034.8712 (RTKLIB static fix-and-hold over the day against GARR's
header ARP, the 0.054 m antenna height included; vertical uncertainty a few cm: other static settings move it
-2 to +3 cm, docs/decisions/0151).  The base is GARR's ARP (header position + antenna height) for both engines;
UPC1's header antenna height is 0, so both report UPC1's ARP, which the truth is.

Span: 05:00-05:20 GPST (1,200 rover epochs, 40 base epochs, every age 0-29 s 40 times).  Over 05:00-06:00
(docs/decisions/0162) the 20-minute thirds gave ours 7/4/16 and RTKLIB 7/2/17 fixes beyond 10 cm, every one at
an age of 20-29 s: the first third has the hour's mix.  Ours runs with the troposphere of the truth (hydrostatic,
`tropo_humidity=0`; our 70 % default sits 4.6 cm lower, where a troposphere-estimated static solution puts UPC1),
once with the ionosphere out of the model (fixing as often as RTKLIB) and once as the default handles it
(`iono_prior=learned`: out of the model once the first fixes show a quiet night).
"""

from __future__ import annotations

import subprocess

import numpy as np
import pytest
from typer.testing import CliRunner

from augnet.gnss.geometry import ecef_to_enu, enu_to_ecef
from tests.conftest import require_tool
from tests.onboard.test_real_data import _read_csv, _read_rtklib_xyz

pytestmark = [pytest.mark.shared_data, pytest.mark.slow, pytest.mark.rtklib]

CATNET = "rinex/catnet-2010-077"
UPC1_TRUTH = np.array([4789013.1051, 176610.1545, 4195034.8712])
# The judge of our defaults (70 % troposphere): RTKLIB static against GARR with the troposphere estimated
# ("est-ztd", docs/decisions/0165, 0173).
UPC1_TRUTH_EST_ZTD = np.array([4789013.0854, 176610.1611, 4195034.8637])
START, END = "2010-03-18T05:00:00", "2010-03-18T05:20:00"
OURS = ["--systems", "G", "--frequencies", "2", "--elevation-mask", "15", "--max-age", "30",
        "--opt", "ionosphere=off", "--opt", "tropo_humidity=0"]
# ... and with the ionosphere as the default handles it (iono_prior=learned: in the model until the first fixes
# show the night's DD ionosphere, ~0.5 cm, then out).
OURS_LEARNED = [*OURS[:8], "--opt", "tropo_humidity=0"]
RTKLIB_CONF = """\
pos1-posmode       =kinematic
pos1-frequency     =l1+2
pos1-soltype       =forward
pos1-elmask        =15
pos1-dynamics      =off
pos1-ionoopt       =brdc
pos1-tropopt       =saas
pos1-sateph        =brdc
pos1-navsys        =1
pos2-armode        =continuous
pos2-arthres       =3
out-solformat      =xyz
out-outhead        =on
ant2-postype       =xyz
ant2-pos1          ={x:.4f}
ant2-pos2          ={y:.4f}
ant2-pos3          ={z:.4f}
"""
# The must-show's limit on a fix's error [m].
MAX_FIX_ERROR_M = 0.10
# After a partial quiet-ionosphere fix the per-km prior's own streak must span the next 30 s base epoch (3
# decisions): the epochs it may stay float (decision 0221; measured 29 from 05:40).
AFTER_QUIET_FIX_FLOAT_EPOCHS = 35


def _garr_arp(path) -> np.ndarray:
    from augnet.gnss.rinex import read_obs

    h = read_obs(path).header
    p = np.asarray(h.approx_position_m, dtype=float)
    return p + enu_to_ecef(np.array([0.0, 0.0, h.antenna_delta_hen_m[0]]), p)


@pytest.fixture(scope="module")
def runs(shared_data, tmp_path_factory):
    """(ours, RTKLIB's): per engine the number of epochs, of fixes, and the fixes' errors [m, 3-D]."""
    exe = require_tool("rnx2rtkp")
    import gzip

    d = shared_data / CATNET
    tmp = tmp_path_factory.mktemp("catnet")
    files = {}
    for name in ("UPC10770.10o", "GARR0770.10o", "brdc0770.10n"):
        files[name] = tmp / name
        files[name].write_bytes(gzip.decompress((d / f"{name}.gz").read_bytes()))
    base = _garr_arp(files["GARR0770.10o"])

    def rtklib(extra: str, name: str):
        conf = tmp / f"{name}.conf"
        conf.write_text(RTKLIB_CONF.format(x=base[0], y=base[1], z=base[2]) + extra)
        pos = tmp / f"{name}.pos"
        subprocess.run([exe, "-k", str(conf), "-ts", START[:10].replace("-", "/"), START[11:], "-te",
                        END[:10].replace("-", "/"), "05:19:59", "-o", str(pos), str(files["UPC10770.10o"]),
                        str(files["GARR0770.10o"]), str(files["brdc0770.10n"])],
                       check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=300)
        return _read_rtklib_xyz(pos)

    theirs = rtklib("", "rtklib")
    theirs_interp = rtklib("misc-timeinterp    =on\n", "rtklib-interp")
    from augnet.cli import _mount, app

    _mount()

    def ours(args):
        out = tmp / "ours.csv"
        r = CliRunner().invoke(app, ["rtk", "--rover", str(files["UPC10770.10o"]), "--base", str(files["GARR0770.10o"]),
                                     "--nav", str(files["brdc0770.10n"]), "--base-pos",
                                     ",".join(f"{v:.4f}" for v in base), "--start", START, "--end", END,
                                     "--out", str(out), *args])
        assert r.exit_code == 0, r.output
        rows = _read_csv(out)
        return rows, [[float(row[k]) for k in ("x_m", "y_m", "z_m")] for row in rows if row["status"] == "fix"]

    def errors(xyz, truth=UPC1_TRUTH):
        return np.linalg.norm(ecef_to_enu(np.asarray(xyz) - truth, truth), axis=-1)

    rows, o_fix = ours(OURS)
    rows_l, l_fix = ours(OURS_LEARNED)
    rows_i, i_fix = ours([*OURS, "--base-interp"])
    rows_li, li_fix = ours([*OURS_LEARNED, "--base-interp"])
    rows_d, d_fix = ours([*OURS[:8], "--base-interp"])  # every model setting at its default
    first_d = next((k for k, row in enumerate(rows_d) if row["status"] == "fix"), len(rows_d))
    t_fix = [p for p, q in theirs.values() if q == 1]
    ti_fix = [p for p, q in theirs_interp.values() if q == 1]
    res = {"ours": (len(rows), len(o_fix), errors(o_fix)), "learned": (len(rows_l), len(l_fix), errors(l_fix)),
           "rtklib": (len(theirs), len(t_fix), errors(t_fix)),
           "ours interp": (len(rows_i), len(i_fix), errors(i_fix)),
           "learned interp": (len(rows_li), len(li_fix), errors(li_fix)),
           "rtklib interp": (len(theirs_interp), len(ti_fix), errors(ti_fix)),
           "defaults interp": (len(rows_d), len(d_fix), errors(d_fix, UPC1_TRUTH_EST_ZTD))}
    print(f"defaults interp: first fix at epoch {first_d}")
    res["defaults first fix"] = first_d
    for k, (n, nf, e) in ((k, v) for k, v in res.items() if isinstance(v, tuple)):
        print(f"{k}: {nf}/{n} fixed, {int(np.sum(e > MAX_FIX_ERROR_M))} beyond 10 cm, "
              f"median {np.median(e) * 100:.1f} cm")
    return res


def test_fixes_at_least_as_often_as_rtklib_and_no_more_errors_beyond_10cm(runs):
    n, n_fix, err = runs["ours"]
    n_t, n_fix_t, err_t = runs["rtklib"]
    assert n == 1200 and n_t >= 1195
    assert n_fix / n >= n_fix_t / n_t
    assert np.sum(err > MAX_FIX_ERROR_M) <= np.sum(err_t > MAX_FIX_ERROR_M)
    assert np.median(err) < 0.04  # the fixes sit on the truth (a wrong integer is 10-20 cm off)


@pytest.mark.xfail(strict=True, reason="in real time (no later base epoch to interpolate from) a 30 s base's "
                   "corrections age to 29 s: vertical scatter 4.5 cm at 25-30 s (satellite clocks, 0.9 mm/s per satellite); 05:00-05:20 ours 1200/1200 fixed, 7 beyond "
                   "10 cm (RTKLIB 1200/1200, 7); 05:00-06:00 3600/3600, 27 (RTKLIB 26)")
def test_no_fix_beyond_10cm(runs):
    _, n_fix, err = runs["ours"]
    assert n_fix > 0 and np.sum(err > MAX_FIX_ERROR_M) == 0


def test_with_the_base_interpolated_fixes_as_often_as_rtklib_and_none_beyond_10cm(runs):
    """The must-show, in post-processing: the 30 s base interpolated to each rover epoch (`--base-interp`; RTKLIB
    misc-timeinterp beside it).  Measured 1,200/1,200 fixed, 0 beyond 10 cm, both; over 05:00-06:00 3,600/3,600,
    0, H95 1.6 / V95 3.5 cm (docs/decisions/0173)."""
    n, n_fix, err = runs["ours interp"]
    n_t, n_fix_t, err_t = runs["rtklib interp"]
    # rnx2rtkp interpolating stops at the span's last base epoch (05:19:30)
    assert n == 1200 and n_t >= 1165
    assert n_fix / n >= n_fix_t / n_t
    assert n_fix > 0 and np.sum(err > MAX_FIX_ERROR_M) == 0
    assert np.median(err) < 0.03


def test_the_learned_prior_on_the_interpolated_base_fixes_most_epochs_none_beyond_10cm(runs):
    """The default ionosphere handling on the interpolated base: float until its first fix (the quiet-ionosphere
    hypothesis after 30 s, decision 0220: 1,168 of 1,200 fixed, first at 32 s; before it 814, on the per-km
    prior), and the interpolation removes the aged-correction errors (7 -> 0 beyond 10 cm; decision 0173)."""
    n, n_fix, err = runs["learned interp"]
    _, _, err_l = runs["learned"]
    assert n == 1200 and n_fix >= 0.6 * n
    assert np.sum(err > MAX_FIX_ERROR_M) < np.sum(err_l > MAX_FIX_ERROR_M)


def test_the_learned_ionosphere_prior_fixes_most_epochs_with_no_more_errors_beyond_10cm(runs):
    """Measured 1,078 of 1,200 fixed (the first two minutes float while the prior is the per-km one), 7 beyond
    10 cm; the per-km prior kept over the hour: 82 beyond 10 cm against 27 (docs/decisions/0162)."""
    n, n_fix, err = runs["learned"]
    _, _, err_t = runs["rtklib"]
    assert n == 1200 and n_fix >= 0.85 * n
    assert np.sum(err > MAX_FIX_ERROR_M) <= np.sum(err_t > MAX_FIX_ERROR_M)


def test_defaults_on_garr_upc1_from_a_cold_start_fix_within_a_minute_none_beyond_10cm(runs):
    """Every model setting at its default (learned ionosphere prior, 70 % troposphere), the base interpolated,
    judged against the est-ztd truth, cold start 05:00 (docs/decisions/0220).  The quiet-ionosphere hypothesis
    (the GF rate over the first 30 s says the DD ionosphere is quiet; a 0.5 cm prior, its fix self-checked)
    and the two-base-epoch agreement give 1,168 of 1,200 fixed, first fix at 32 s, 0 beyond 10 cm (main: 814,
    first fix at 386 s).  With the rate's base part from the base's own 30 s arcs and the quiet decisions taken
    from the first epoch (decision 0221): 1,170, first fix at 30 s (complete, so the level is learned from it)."""
    n, n_fix, err = runs["defaults interp"]
    assert n == 1200 and n_fix > 0 and np.sum(err > MAX_FIX_ERROR_M) == 0
    # a quiet fix rests on a 30 s GF rate and two base epochs (30 s apart): the first fix within two of them
    assert runs["defaults first fix"] <= 60
    # once fixed, it stays fixed (the learned level follows the complete quiet fix)
    assert n_fix >= n - runs["defaults first fix"] - 5


@pytest.mark.xfail(strict=True, reason="a new fix's decisions must span two base epochs and the GF rate needs 30 s: "
                   "the first fix comes at the first base epoch after the start, 30 s: cold starts 05:00 / 05:20 / "
                   "05:40 ours 1,170 / 1,170 / 1,141 of 1,200, RTKLIB timeinterp 1,171 of 1,171 each (it fixes from the first "
                   "epoch with the ionosphere out of its model); 0 beyond 10 cm either (decisions 0220, 0221)")
def test_defaults_on_garr_upc1_from_three_cold_starts(runs):
    """The brief's figure on the test's window: with our defaults fix at least as many epochs as RTKLIB."""
    n, n_fix, err = runs["defaults interp"]
    _, n_fix_t, _ = runs["rtklib interp"]
    assert n_fix >= n_fix_t and np.sum(err > MAX_FIX_ERROR_M) == 0


@pytest.fixture(scope="module")
def later_cold_starts(shared_data, tmp_path_factory):
    """Ours at its defaults with `--base-interp` from cold starts at 05:20 and 05:40 (20 minutes each): per start
    the number of epochs, the first fixed epoch and the fixes' errors against the est-ztd truth [m, 3-D]."""
    import gzip

    d = shared_data / CATNET
    tmp = tmp_path_factory.mktemp("catnet-cold")
    files = {}
    for name in ("UPC10770.10o", "GARR0770.10o", "brdc0770.10n"):
        files[name] = tmp / name
        files[name].write_bytes(gzip.decompress((d / f"{name}.gz").read_bytes()))
    base = _garr_arp(files["GARR0770.10o"])
    from augnet.cli import _mount, app

    _mount()
    res = {}
    for start, end in (("05:20:00", "05:40:00"), ("05:40:00", "06:00:00")):
        out = tmp / f"ours-{start[:2]}{start[3:5]}.csv"
        r = CliRunner().invoke(app, ["rtk", "--rover", str(files["UPC10770.10o"]), "--base", str(files["GARR0770.10o"]),
                                     "--nav", str(files["brdc0770.10n"]), "--base-pos",
                                     ",".join(f"{v:.4f}" for v in base), "--start", f"2010-03-18T{start}",
                                     "--end", f"2010-03-18T{end}", "--out", str(out), *OURS[:8], "--base-interp"])
        assert r.exit_code == 0, r.output
        rows = _read_csv(out)
        fixed = [[float(row[k]) for k in ("x_m", "y_m", "z_m")] for row in rows if row["status"] == "fix"]
        first = next((k for k, row in enumerate(rows) if row["status"] == "fix"), len(rows))
        err = np.linalg.norm(ecef_to_enu(np.asarray(fixed).reshape(-1, 3) - UPC1_TRUTH_EST_ZTD, UPC1_TRUTH_EST_ZTD),
                             axis=-1)
        print(f"defaults interp from {start}: {len(fixed)}/{len(rows)} fixed, first at epoch {first}, "
              f"{int(np.sum(err > MAX_FIX_ERROR_M))} beyond 10 cm")
        res[start] = (len(rows), first, err)
    return res


@pytest.mark.parametrize("start", ["05:20:00", "05:40:00"])
def test_defaults_from_later_cold_starts_fix_at_the_second_base_epoch_none_beyond_10cm(later_cold_starts, start):
    """Decision 0221: the quiet-ionosphere rate's base part from the base's own 30 s arcs (the base file's past
    before the start) gives a usable rate after 30 s where the SD slope read the interpolated base's GF noise:
    first fix at 30 s from both starts (before: 62 s and 182 s), 1,170 and 1,141 of 1,200 fixed, 0 beyond 10 cm
    (from 05:40 the quiet fix is partial, 11 of 12: no level is learned from it and the per-km prior's own streak
    spans the next base epoch)."""
    n, first, err = later_cold_starts[start]
    assert n == 1200 and err.size > 0 and np.sum(err > MAX_FIX_ERROR_M) == 0
    # a quiet fix rests on a 30 s GF rate and two base epochs: the first fix within two of them
    assert first <= 60
    assert err.size >= n - first - AFTER_QUIET_FIX_FLOAT_EPOCHS
