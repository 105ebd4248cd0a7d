"""Machine yardstick shared by every `augnet bench` (issue 17): RTKLIB rnx2rtkp's CPU time per epoch on
../shared/data/rinex/static-1m-2024, measured in the same run, so figures can be stated in yardstick units."""

from __future__ import annotations

import shutil

YARDSTICK_KEY = "yardstick_rnx2rtkp_ms_per_epoch"


def yardstick_ms() -> float | None:
    """RTKLIB rnx2rtkp's CPU time per epoch [ms] on static-1m-2024, GPS + Galileo + BeiDou + QZSS L1+L2 (the
    larger configuration of `augnet bench rtk`); None without the data or rnx2rtkp."""
    from augnet.bench import rtk

    exe = shutil.which("rnx2rtkp")
    if exe is None or not rtk.DATA.is_dir():
        return None
    return 1e3 * rtk.run_rtklib(exe, rtk.CONFIGS[-1][1])["per_epoch_s"]


def annotate(results: dict, yard_ms: float | None, per_epoch_suffix: str = "_ms_per_epoch") -> dict:
    """Add the yardstick to a bench's JSON figures and each `*<suffix>` figure divided by it (`*_yardsticks`);
    a None yardstick is stated (key present, value None) rather than silently left out."""
    results[YARDSTICK_KEY] = None if yard_ms is None else round(yard_ms, 3)
    if yard_ms:
        for k in [k for k in list(results) if k.endswith(per_epoch_suffix) and k != YARDSTICK_KEY]:
            results[k.replace(per_epoch_suffix, "_yardsticks")] = round(results[k] / yard_ms, 2)
    return results


def describe(yard_ms: float | None) -> str:
    """One printed line saying what the yardstick measured, or why there is none."""
    if yard_ms is None:
        return "  no yardstick: rnx2rtkp or ../shared/data/rinex/static-1m-2024 absent"
    return (f"  yardstick: RTKLIB rnx2rtkp {yard_ms:.3f} ms per epoch on static-1m-2024 (GECJ L1+L2); "
            "'_yardsticks' = figure / yardstick")
