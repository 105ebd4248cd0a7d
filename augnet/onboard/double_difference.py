"""The RTK measurement model: zero differences -> single differences (rover - base) -> double-difference
rows (innovations, design matrix, covariance) of phase and code against one reference satellite per
system and frequency slot.

The filter's state holds single-difference ambiguities (and ionospheres); the DDs are formed here, in
the measurement model, so satellites rise and set and references change without touching the state.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from augnet.gnss.antex import AntennaSetup
from augnet.gnss.constants import SPEED_OF_LIGHT_M_S
from augnet.onboard import correction_age
from augnet.onboard.atmosphere import DEFAULT_RELATIVE_HUMIDITY, saastamoinen_m
from augnet.onboard.observations import BAND_FREQ_HZ, SYSTEM_BANDS, EpochObs
from augnet.onboard.spp import SatPositions, azimuth_elevation_from, geometric_range, receiver_frame

# Elevation floor of the noise model [rad sine]: sin(el) is clipped here so a satellite at the horizon
# gets a large but finite variance.
MIN_SIN_ELEVATION = 0.05
# A DD ambiguity counts as established (reference choice, slip screening) below this sigma [cycles].
AMB_KNOWN_SIGMA_CYC = 0.5


@dataclass
class ZeroDifferences:
    """Observed minus modelled (range, troposphere, satellite clock) per satellite and slot [m] for
    phase and code, with the line-of-sight unit vectors and elevations [rad] at the receiver."""
    phase: np.ndarray
    code: np.ndarray
    los: np.ndarray
    el: np.ndarray


@dataclass
class SingleDifferences:
    """Rover minus base zero differences [m] of the first `nf` slots, with the rover's geometry."""
    phase: np.ndarray
    code: np.ndarray
    los: np.ndarray
    el: np.ndarray


@dataclass
class Group:
    """The DD rows of one system and slot at one epoch."""
    sats: list[int]  # indices into the epoch's satellite list; first is the reference
    slot: int


@dataclass
class DDIndex:
    """One epoch's double differences as parallel index arrays (one entry per non-reference satellite
    and slot): epoch satellite indices, slot, group, and the state indices of the SD ambiguities and
    (when estimated) SD ionospheres involved."""
    k: np.ndarray
    ref: np.ndarray
    f: np.ndarray
    group: np.ndarray
    i: np.ndarray
    iref: np.ndarray
    ion: np.ndarray | None
    ion_ref: np.ndarray | None


@dataclass
class Rows:
    """DD measurement rows: innovations v [m], design matrix H, covariance R, and kind (1 phase, 0 code)."""
    v: np.ndarray
    H: np.ndarray
    R: np.ndarray
    kind: np.ndarray

    def select(self, keep: np.ndarray | None) -> "Rows":
        """The rows where `keep` is true (all of them for None)."""
        if keep is None or keep.all():
            return self
        return Rows(self.v[keep], self.H[keep], self.R[np.ix_(keep, keep)], self.kind[keep])

    def about(self, x_pos: np.ndarray, x_lin: np.ndarray) -> "Rows":
        """The innovations against a state position x_pos for rows linearised at x_lin."""
        return Rows(self.v - self.H[:, :3] @ (x_pos - x_lin), self.H, self.R, self.kind)


def first_wavelength(system: str) -> float:
    """Wavelength [m] of a system's first frequency (slot 0: L1, E1, B1I), the ionosphere's reference."""
    return SPEED_OF_LIGHT_M_S / BAND_FREQ_HZ[(system, SYSTEM_BANDS[system][0])]


def zero_differences(obs: EpochObs, rx_m: np.ndarray, sp: SatPositions,
                     antenna: AntennaSetup | None = None,
                     humidity: float = DEFAULT_RELATIVE_HUMIDITY) -> ZeroDifferences:
    """Observed minus modelled phase and code of one receiver at position rx_m (Saastamoinen's troposphere
    with relative humidity `humidity`; 0: its hydrostatic part only). With `antenna` (its ANTEX calibration and
    ARP offset), the observations first get its phase-centre correction, so rx_m is the receiver's marker
    (`augnet.gnss.antex.AntennaSetup`)."""
    rng, los = geometric_range(np.where(sp.valid[:, None], sp.position_m, rx_m + 1.0), rx_m)
    llh, rot = receiver_frame(rx_m)
    az, el = azimuth_elevation_from(rx_m, rot, np.where(sp.valid[:, None], sp.position_m, rx_m + np.array([0, 0, 1.0])))
    trop = saastamoinen_m(llh[0], llh[2], el, humidity)
    model = rng + trop - SPEED_OF_LIGHT_M_S * sp.clock_s
    phase = obs.phase_cyc * obs.wavelength_m - model[:, None]
    code = obs.code_m - model[:, None]
    if antenna is not None:
        corr = antenna.correction_m(az, el, obs.sats, obs.signal)
        phase = phase + corr
        code = code + corr
    return ZeroDifferences(phase, code, los, el)


def single_differences(rover: ZeroDifferences, base: ZeroDifferences, nf: int) -> SingleDifferences:
    """Rover minus base, first nf slots, with the rover's lines of sight and elevations."""
    return SingleDifferences(rover.phase[:, :nf] - base.phase[:, :nf], rover.code[:, :nf] - base.code[:, :nf],
                             rover.los, rover.el)


def phase_variance(el: np.ndarray, sigma_a_m: float, sigma_b_m: float) -> np.ndarray:
    """Carrier-phase variance [m^2] of one receiver: a^2 + b^2 / sin^2(el) (RTKLIB's model)."""
    s = np.maximum(np.sin(el), MIN_SIN_ELEVATION)
    return sigma_a_m**2 + sigma_b_m**2 / s**2


def choose_groups(systems, sys_: np.ndarray, ok: np.ndarray, el: np.ndarray, nf: int,
                  amb_var: np.ndarray) -> list[Group]:
    """One group per system and slot with at least two usable satellites; its reference is the highest
    satellite among those with an established ambiguity (variance `amb_var` below AMB_KNOWN_SIGMA_CYC^2),
    or among all when none is."""
    known = amb_var < AMB_KNOWN_SIGMA_CYC**2
    groups = []
    for s in systems:
        in_sys = sys_ == s
        for f in range(nf):
            members = np.flatnonzero(ok[:, f] & in_sys)
            if len(members) < 2:
                continue
            est = members[known[members, f]]
            pool = est if len(est) else members
            ref = int(pool[np.argmax(el[pool])])  # the first of equal elevations, as max() takes
            groups.append(Group([ref] + [int(k) for k in members if k != ref], f))
    return groups


def dd_index(groups: list[Group], amb_state, ion_state=None) -> DDIndex:
    """The epoch's double differences as index arrays; `amb_state(k, f)` and `ion_state(k)` give the state
    index of satellite k's SD ambiguity in slot f and of its SD ionosphere (None: not estimated)."""
    ks, refs, fs, gs = [], [], [], []
    for gi, g in enumerate(groups):
        n = len(g.sats) - 1
        ks.extend(g.sats[1:])
        refs.extend([g.sats[0]] * n)
        fs.extend([g.slot] * n)
        gs.extend([gi] * n)
    k = np.array(ks, dtype=int)
    ref = np.array(refs, dtype=int)
    f = np.array(fs, dtype=int)
    amb = np.array([amb_state(a, b) for a, b in zip(ks, fs)], dtype=int)
    amb_ref = np.array([amb_state(a, b) for a, b in zip(refs, fs)], dtype=int)
    if ion_state is not None:
        ion = np.array([ion_state(a) for a in ks], dtype=int)
        ion_ref = np.array([ion_state(a) for a in refs], dtype=int)
    else:
        ion = ion_ref = None
    return DDIndex(k, ref, f, np.array(gs, dtype=int), amb, amb_ref, ion, ion_ref)


def dd_rows(dd: DDIndex, sd: SingleDifferences, wl: np.ndarray, mu: np.ndarray, var_sd: np.ndarray,
            x: np.ndarray, code_phase_ratio: float, var_common: np.ndarray | None = None) -> Rows:
    """Innovations, design matrix and covariance of the epoch's DD phase rows then DD code rows, for the
    state x with the SDs formed at the linearisation point (so the innovations carry no position term).

    wl: wavelengths [m] per satellite and slot; mu: the ionosphere's scale (f1 / f)^2; var_sd: SD phase
    variances [m^2]; code variances are those times code_phase_ratio^2; var_common: per satellite, the
    variance [m^2] of an SD error common to its slots, phase and code (aged corrections: `correction_age`)."""
    nx = len(x)
    m = len(dd.k)
    ar = np.arange(m)
    k, ref, f = dd.k, dd.ref, dd.f
    geo = -(sd.los[k] - sd.los[ref])
    H = np.zeros((2 * m, nx))
    H[:m, :3] = geo
    H[m:, :3] = geo
    H[ar, dd.i] = wl[k, f]
    H[ar, dd.iref] = -wl[ref, f]
    if dd.ion is not None:
        # phase advance -mu I, code delay +mu I (SD ionosphere on the first frequency per satellite)
        H[ar, dd.ion] = -mu[k, f]
        H[ar, dd.ion_ref] = mu[ref, f]
        H[m + ar, dd.ion] = mu[k, f]
        H[m + ar, dd.ion_ref] = -mu[ref, f]
    y = np.concatenate((sd.phase[k, f] - sd.phase[ref, f], sd.code[k, f] - sd.code[ref, f]))
    v = y - H[:, 3:] @ x[3:]
    same = dd.group[:, None] == dd.group[None, :]
    Rp = np.diag(var_sd[k, f]) + same * var_sd[ref, f][:, None]
    R = np.zeros((2 * m, 2 * m))
    R[:m, :m] = Rp
    R[m:, m:] = Rp * code_phase_ratio**2
    if var_common is not None and np.any(var_common > 0.0):
        A = correction_age.dd_covariance(k, ref, var_common)
        R += np.block([[A, A], [A, A]])
    kind = np.concatenate((np.ones(m, dtype=int), np.zeros(m, dtype=int)))
    return Rows(v, H, R, kind)


def phase_residuals(dd: DDIndex, rows: np.ndarray, sd: SingleDifferences, wl: np.ndarray, mu: np.ndarray,
                    x_lin: np.ndarray, x: np.ndarray) -> np.ndarray:
    """DD phase residuals [m] of a state x on some DD rows, the SDs formed at the linearisation point x_lin."""
    dx = x[:3] - x_lin
    k, ref, f = dd.k[rows], dd.ref[rows], dd.f[rows]
    y = sd.phase[k, f] - sd.phase[ref, f]
    pred = -(sd.los[k] - sd.los[ref]) @ dx + wl[k, f] * x[dd.i[rows]] - wl[ref, f] * x[dd.iref[rows]]
    if dd.ion is not None:
        pred = pred - mu[k, f] * x[dd.ion[rows]] + mu[ref, f] * x[dd.ion_ref[rows]]
    return y - pred


def slipped_keys(bad: np.ndarray, dd: DDIndex, known: np.ndarray, sats: list[str]) -> set[tuple[str, int]]:
    """Which SD ambiguities (satellite, slot) to reset given failing phase rows `bad`: the row's satellite,
    or the group's reference when at least half of its rows with established ambiguities (`known`) fail
    together."""
    out = set()
    for g in np.unique(dd.group):
        idx = np.flatnonzero((dd.group == g) & known)
        if len(idx) == 0:
            continue
        nbad = int(np.count_nonzero(bad[idx]))
        if nbad >= max(2, (len(idx) + 1) // 2):
            out.add((sats[dd.ref[idx[0]]], int(dd.f[idx[0]])))
        else:
            out.update((sats[dd.k[r]], int(dd.f[r])) for r in idx if bad[r])
    return out
