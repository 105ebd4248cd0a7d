"""Post-processing like RTKLIB's rnx2rtkp: rover and base observation files + navigation -> solutions.

Epochs are matched by time: each rover epoch is processed with the latest base epoch not after it
(within half an interval of tolerance), so a missing base epoch ages the corrections rather than
stopping the run; the filter itself decides when they are too old.  A base file whose MARKER TYPE is
NON_PHYSICAL (a network VRS) is treated as one: its residual ionosphere is estimated.  With the receivers'
antennas (`base_antenna`, `rover_antenna`: ANTEX calibrations and header ARP offsets, `augnet rtk --antex`),
the base position and the solution are the markers' (RTKLIB with ant1/ant2-anttype=*).
"""

from __future__ import annotations

import copy
from typing import Iterator

import numpy as np

from augnet.gnss.antex import AntennaSetup
from augnet.gnss.ephemeris import NavigationData
from augnet.onboard.base_interpolation import MAX_INTERPOLATION_SPAN_S, flag_slips, interpolate
from augnet.onboard.observations import ObsArrays, choose_signals, epochs
from augnet.onboard.rtk import RtkFilter, RtkOptions, RtkSolution

# A base epoch up to this much [s] after the rover epoch still counts as simultaneous (time-tag
# rounding between receivers).
EPOCH_MATCH_TOLERANCE_S = 0.05


def process(rover: ObsArrays, base: ObsArrays, nav: NavigationData, base_position_m,
            options: RtkOptions | None = None, base_is_vrs: bool | None = None,
            base_antenna: AntennaSetup | None = None, rover_antenna: AntennaSetup | None = None,
            interpolate_base: bool = False) -> Iterator[RtkSolution]:
    """Solutions for every rover epoch, in time order.  `base_is_vrs`: None takes it from the base
    file's MARKER TYPE.  `interpolate_base`: a rover epoch between two base epochs gets the base's
    observations interpolated to its time (base_interpolation.py; RTKLIB's misc-timeinterp)."""
    opt = options or RtkOptions()
    rsig = choose_signals(rover, opt.n_slots, opt.systems)
    bsig = choose_signals(base, opt.n_slots, opt.systems)
    rov_epochs = epochs(rover, opt.n_slots, opt.systems, rsig)
    base_epochs = epochs(base, opt.n_slots, opt.systems, bsig)
    base_times = np.array([e.time for e in base_epochs])
    order = np.argsort(base_times, kind="stable")
    base_times = base_times[order]
    if base_is_vrs is None:
        base_is_vrs = getattr(base, "non_physical", False)
    flt = RtkFilter(nav, base_position_m, opt, base_is_vrs=base_is_vrs, base_antenna=base_antenna,
                    rover_antenna=rover_antenna)
    if interpolate_base:
        flag_slips([base_epochs[i] for i in order])
    # the base's past before the rover's first epoch: the quiet-ionosphere rate's base part (decision 0221)
    t_first = rov_epochs[0].time if rov_epochs else np.inf
    history = [base_epochs[i] for i in order if base_epochs[i].time < t_first - EPOCH_MATCH_TOLERANCE_S]
    if not interpolate_base:
        # on copies: the base epoch in force at the first rover epoch is handed on with its own LLI only
        history = [copy.copy(b) for b in history]
        flag_slips(history)
    for b in history:
        flt.observe_base_history(b)
    used_from = -1  # the base epoch whose loss-of-lock flags were last handed on
    for ep in rov_epochs:
        k = int(np.searchsorted(base_times, ep.time + EPOCH_MATCH_TOLERANCE_S, side="right")) - 1
        b = base_epochs[order[k]] if k >= 0 else None
        if (interpolate_base and b is not None and k + 1 < len(base_times)
                and ep.time - base_times[k] > EPOCH_MATCH_TOLERANCE_S
                and base_times[k + 1] - base_times[k] <= MAX_INTERPOLATION_SPAN_S):
            b = interpolate(b, base_epochs[order[k + 1]], ep.time, nav, base_position_m,
                            first_after_b0=used_from != k, humidity=opt.tropo_humidity)
        used_from = k
        yield flt.step(ep, b)
