"""Where the baseline filter's states live.

x = [zwd_a, zwd_b, then per satellite a block: SD slant ionosphere on f1 [m], SD ambiguities N1, N2 [cycles], and
(when modelled) SD code multipath on f1, f2 [m] and SD phase multipath on f1, f2 [m]]. The blocks are kept dense
(`StateLayout(reuse_freed=False)`): a satellite's removal moves the later ones down, in order.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from augnet.centre.baseline_config import BaselineConfig
from augnet.gnss.state_layout import StateLayout

ZWD_A, ZWD_B = 0, 1  # the residual zenith wet delays of stations a and b [m]
IONO, N1 = 0, 1  # offsets in a satellite's block: SD ionosphere, then N1 and N2 (N1 + 1)


@dataclass(frozen=True)
class SatelliteBlock:
    """The offsets of the multipath states within a satellite's block (None when not modelled) and its size."""

    code_multipath: int | None
    phase_multipath: int | None
    size: int

    @classmethod
    def from_config(cls, cfg: BaselineConfig) -> "SatelliteBlock":
        code = 3 if cfg.code_multipath_share > 0 else None
        phase = (3 + 2 * (code is not None)) if cfg.phase_multipath_share > 0 else None
        return cls(code, phase, 3 + 2 * (code is not None) + 2 * (phase is not None))

    @property
    def has_multipath(self) -> bool:
        return self.code_multipath is not None or self.phase_multipath is not None


def zwd_prior(cfg: BaselineConfig) -> np.ndarray:
    """Covariance of (zwd_a, zwd_b) from the prior of each and of their difference: zwd_a = c - r/2,
    zwd_b = c + r/2 with c the common and r the relative residual wet delay."""
    vc = max(cfg.zwd_prior_sigma_m**2 - cfg.zwd_relative_prior_sigma_m**2 / 4.0, 0.0)
    vr = cfg.zwd_relative_prior_sigma_m**2
    return np.array([[vc + vr / 4.0, vc - vr / 4.0], [vc - vr / 4.0, vc + vr / 4.0]])


def new_state(cfg: BaselineConfig) -> StateLayout:
    return StateLayout(np.zeros(2), zwd_prior(cfg), reuse_freed=False)


def add_satellite(state: StateLayout, block: SatelliteBlock, sat: str, iono_var_m2: float, n1: float, n2: float,
                  amb_var_cyc2: float, code_mp_var_m2: float, phase_mp_var_m2: float,
                  code_mp_var2_m2: float | None = None) -> None:
    """A satellite's block: the ionosphere at zero, the ambiguities from phase minus code, no multipath yet
    (`code_mp_var2_m2`: the second frequency's code multipath variance, default the first's)."""
    values = np.zeros(block.size)
    values[IONO], values[N1], values[N1 + 1] = 0.0, n1, n2
    variances = np.zeros(block.size)
    variances[IONO], variances[N1], variances[N1 + 1] = iono_var_m2, amb_var_cyc2, amb_var_cyc2
    code2 = code_mp_var_m2 if code_mp_var2_m2 is None else code_mp_var2_m2
    for off, var, var2 in ((block.code_multipath, code_mp_var_m2, code2),
                           (block.phase_multipath, phase_mp_var_m2, phase_mp_var_m2)):
        if off is not None:
            variances[off], variances[off + 1] = var, var2
    state.add(sat, values, variances)


def restart_ambiguities(state: StateLayout, sat: str, n1: float, n2: float, amb_var_cyc2: float) -> None:
    """The satellite's SD ambiguities start afresh, uncorrelated (its ionosphere and multipath carry on)."""
    state.reset(state.index(sat) + N1, [n1, n2], [amb_var_cyc2, amb_var_cyc2])


def dd_indices(state: StateLayout, sats, ks, ref_k, offset: int) -> tuple[np.ndarray, np.ndarray]:
    """State indices of a quantity (`offset` in the block) of satellites `sats[ks]` and of their references."""
    ps = np.array([state.index(str(sats[k])) for k in ks], dtype=int) + offset
    pr = np.array([state.index(str(sats[ref_k[k]])) for k in ks], dtype=int) + offset
    return ps, pr
