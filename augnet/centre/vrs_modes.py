"""What a VRS carries per satellite, and how good the centre thinks it is (issue 14, decision 0230).

Three modes, per point and satellite:

- `network`: the network fixed the satellite on the baselines around the point; the interpolated DD
  ionosphere and troposphere are applied (vrs.synthesize).
- `float-model`: not fixed, but the baselines' float DD ionosphere (levelled phase, `BaselineEpoch.iono_float_m`
  and its variance) chained to the master and interpolated to the point gives a correction whose sigma is
  clearly below the single-base error it would replace.
- `single-base`: the master's observations moved geometrically only; the rover sees the DD ionosphere over
  the distance to the master unreduced.

The single-base error is the learned level of the DD ionosphere (the day's level, ppm of the distance,
vertical; ionosphere_prior.IonospherePrior.level_ppm) times the distance to the master. A float model is
used only where its sigma is below `FLOAT_MODEL_MARGIN` times that: a correction no better than what it
replaces only adds its own noise. The float model is OFF by default (`float_model=False`): it has not been
shown to help on real data (decision 0230).

Everything is vectorised over points x satellites.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

NETWORK, FLOAT_MODEL, SINGLE_BASE = 0, 1, 2
MODE_LABELS = {NETWORK: "network", FLOAT_MODEL: "float-model", SINGLE_BASE: "single-base"}
# A float model must be at most half the single-base error it replaces ("clearly below", issue 14): then the
# rover's ionosphere error at least halves, which a 1-sigma estimate's own error (~30 % on a few epochs of
# levelled phase) cannot reverse.
FLOAT_MODEL_MARGIN = 0.5
PPM = 1e-6  # parts per million of a distance


def single_base_sigma_m(distance_m, level_ppm: float) -> np.ndarray:
    """1-sigma [m] of the DD ionosphere a single-base VRS leaves to its rover: the learned level [ppm, vertical]
    over the distance to the master [m] (network-rtk.md: the DD ionosphere grows with the baseline)."""
    d = np.asarray(distance_m, float)
    if not np.isfinite(level_ppm) or level_ppm < 0:
        raise ValueError(f"ionosphere level must be a finite non-negative ppm, got {level_ppm!r}")
    if np.any(d < 0):
        raise ValueError("distance to the master must be non-negative")
    return level_ppm * PPM * d


def select_modes(corrected, single_sigma_m, float_sigma_m=None, float_model: bool = False,
                 margin: float = FLOAT_MODEL_MARGIN, network_sigma_m=None):
    """Mode and centre 1-sigma [m] per point and satellite.

    corrected (T, S) bool: network-corrected satellites; single_sigma_m (T,) or (T, S): the single-base error;
    float_sigma_m (T, S): the float model's sigma at the point (NaN where there is none); network_sigma_m (T, S):
    the network corrections' sigma where known (NaN: not estimated). Returns (modes int8 (T, S), sigma (T, S))."""
    corr = np.atleast_2d(np.asarray(corrected, bool))
    if not 0.0 < margin <= 1.0:
        raise ValueError(f"float-model margin must be in (0, 1], got {margin!r}")
    single = np.asarray(single_sigma_m, float)
    single = np.broadcast_to(single[:, None] if single.ndim == 1 else single, corr.shape)
    modes = np.where(corr, NETWORK, SINGLE_BASE).astype(np.int8)
    net_sig = (np.full(corr.shape, np.nan) if network_sigma_m is None
               else np.broadcast_to(np.asarray(network_sigma_m, float), corr.shape))
    sigma = np.where(corr, net_sig, single)
    if float_model and float_sigma_m is not None:
        fs = np.broadcast_to(np.asarray(float_sigma_m, float), corr.shape)
        with np.errstate(invalid="ignore"):
            better = ~corr & np.isfinite(fs) & (fs >= 0) & (fs < margin * single)
        modes = np.where(better, FLOAT_MODEL, modes).astype(np.int8)
        sigma = np.where(better, fs, sigma)
    return modes, sigma


@dataclass
class ModeTally:
    """Satellite-epochs per mode and the centre's sigmas, over a run (for `augnet vrs`'s summary)."""

    counts: dict = field(default_factory=lambda: {m: 0 for m in MODE_LABELS})
    sigmas: dict = field(default_factory=lambda: {m: [] for m in MODE_LABELS})
    epochs: dict = field(default_factory=lambda: {m: 0 for m in MODE_LABELS})

    def add(self, modes, sigma) -> None:
        """One epoch's carried satellites: modes (S,) int8 and sigma (S,) [m] (NaN: not estimated)."""
        modes = np.asarray(modes).reshape(-1)
        sigma = np.asarray(sigma, float).reshape(-1)
        if modes.shape != sigma.shape:
            raise ValueError(f"modes {modes.shape} and sigma {sigma.shape} differ")
        for m in MODE_LABELS:
            sel = modes == m
            n = int(sel.sum())
            self.counts[m] += n
            self.epochs[m] += n > 0
            s = sigma[sel]
            self.sigmas[m].extend(s[np.isfinite(s)].tolist())

    def lines(self) -> list[str]:
        total = sum(self.counts.values())
        out = []
        for m, label in MODE_LABELS.items():
            n = self.counts[m]
            share = f"{n / total:.0%}" if total else "-"
            s = np.asarray(self.sigmas[m])
            if not n:
                sig = ""
            elif s.size == 0:
                sig = "; centre sigma not estimated"
            else:
                sig = (f"; centre 1-sigma median {np.median(s) * 100:.1f} cm, p95 {np.percentile(s, 95) * 100:.1f} "
                       f"cm ({s.size} of {n} with a sigma)")
            out.append(f"VRS carries {label}: {n} satellite-epochs ({share}) in {self.epochs[m]} epochs{sig}")
        return out
