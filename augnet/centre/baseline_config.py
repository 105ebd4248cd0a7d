"""The network engine's settings: one table (`BaselineConfig`) for the baseline filter, its ambiguity fixing, its
ionosphere prior and the network's ionosphere hints and model.

Each row states its unit, meaning and source; `augnet vrs --opt NAME=VALUE` and the reference page
`docs/options/centre.md` (`python -m augnet.centre.baseline_config`) are generated from it. How the values were
found is in `docs/decisions/0101`-`0106`.
"""

from __future__ import annotations

from dataclasses import dataclass

from augnet.gnss.ambiguity import FixPolicy
from augnet.options import setting

_NRTK = "network-rtk.md"
_SIM = "network-70km simulation, docs/decisions"


@dataclass(frozen=True)
class BaselineConfig:
    elevation_mask_deg: float = setting(10.0, unit="deg", doc="satellites below this at either station are not used")
    ref_min_elevation_deg: float = setting(
        20.0, unit="deg", doc="a system's reference satellite (the highest healthy one) is kept while it stays "
        "above this")
    # --- observation noise and multipath
    phase_sigma_m: float = setting(
        0.0021, unit="m", doc="undifferenced phase sigma s in sigma^2(el) = s^2 + s^2 / sin^2(el); 3 mm at zenith",
        source=f"RTKLIB a = b weighting; geodetic station figures, {_NRTK}")
    code_sigma_m: float = setting(
        0.21, unit="m", doc="undifferenced code sigma s, as for the phase; 0.3 m at zenith",
        source=f"RTKLIB a = b weighting; geodetic station figures, {_NRTK}")
    code_correlation_inflation: float = setting(1.0, doc="scales the whole code sigma (white and multipath)")
    code_sigma_second_factor: float = setting(
        1.0, doc="the second frequency's code sigma (white and multipath) relative to the first's; real L2 P(Y) "
        "code is 1.3-2.0 times noisier than L1 C/A above 20 deg (catnet MP2/MP1)",
        source="docs/simulator-calibration.md; decision 0272")
    code_multipath_share: float = setting(
        0.5, doc="share of the code variance carried as first-order Gauss-Markov multipath states (SD per "
        "satellite and frequency) instead of white noise; 0: white noise only",
        source="decision 0101")
    code_multipath_tau_s: float = setting(120.0, unit="s", doc="correlation time of the code multipath",
                                          source="decision 0101")
    phase_multipath_share: float = setting(0.3, doc="share of the phase variance carried as multipath states",
                                           source="decision 0101")
    phase_multipath_tau_s: float = setting(120.0, unit="s", doc="correlation time of the phase multipath",
                                           source="decision 0101")
    # --- troposphere
    zwd_prior_sigma_m: float = setting(0.10, unit="m", doc="prior of each station's residual zenith wet delay")
    zwd_relative_prior_sigma_m: float = setting(
        0.03, unit="m", doc="prior of the difference of the two stations' residual zenith wet delays (the DD "
        "troposphere depends on it; the wet field is smooth over tens of km)")
    zwd_random_walk_m2_s: float = setting(2.0e-8, unit="m^2/s", doc="random walk of the residual zenith wet delays "
                                          "(a few mm to a cm per sqrt(hour))")
    # --- ionosphere prior (augnet/centre/ionosphere_prior.py)
    iono_prior_ppm: float = setting(
        1.5, unit="ppm", doc="default SD ionosphere prior in the integer decision, in ppm of the baseline length, "
        "vertical; a quiet mid-latitude day's DD ionosphere", source=f"DD 1-4 ppm on a quiet day, {_NRTK}; "
        "decision 0102")
    iono_prior_min_m: float = setting(0.01, unit="m", doc="floor of a satellite's SD ionosphere prior sigma")
    iono_rate_ppm_sqrt_s: float = setting(0.05, unit="ppm/sqrt(s)",
                                          doc="least random-walk rate of the SD ionosphere states")
    iono_shell_height_km: float | None = setting(
        350.0, unit="km", doc="single-layer shell height mapping the vertical ppm to slant; none: the baseline's "
        "prior takes the same slant figure at every elevation (the network's hints and ionosphere model still map "
        "at 350 km)", source="Klobuchar's shell; decision 0100")
    iono_prior_adapt: float = setting(
        1.2, doc="the day's prior is this times the 95 % upper bound of the RMS of the fixed satellites' DD "
        "ionosphere; 0: no learning", source="decision 0102")
    iono_prior_adapt_tau_s: float = setting(300.0, unit="s", doc="time constant of a baseline's own running mean "
                                            "square of its fixed satellites' DD ionosphere")
    iono_day_min_sats: int = setting(
        4, doc="fixed satellites needed before the day's level replaces the default prior, lower or higher (the "
        "network keeps a higher level until twice this many show a lower one)", source="decision 0102")
    iono_day_floor_ppm: float = setting(0.7, unit="ppm", doc="floor of the day's level", source="decision 0102")
    iono_state_prior_ppm: float = setting(
        10.0, unit="ppm", doc="the filter state's own SD ionosphere prior, wide enough for a storm: the prior in "
        "force enters the integer decision only, as a DD ionosphere pseudo-observation (a state pulled by a prior "
        "the day disproves cannot be undone later)", source="decision 0103")
    activity_lag_s: float = setting(
        10.0, unit="s", doc="lag of the long SD geometry-free increments that measure the ionosphere's rate "
        "(at least three epochs)")
    activity_tau_epochs: float = setting(30.0, unit="epochs", doc="smoothing of the increments' mean squares")
    activity_min_samples: int = setting(40, doc="long increments needed before the measured rate counts")
    iono_activity_ppm_per_rate: float = setting(
        150.0, unit="ppm per ppm/sqrt(s)", doc="before the day's level is known the prior in force is raised to "
        "this times the measured rate, and nothing is committed before the rate is known; 0: off; a network in "
        "service should fit it to its own history", source="decision 0103")
    activity_rate_margin: float = setting(1.5, doc="the SD ionosphere states' random walk: the configured rate or "
                                          "this times the measured one, whichever is higher")
    # --- ambiguity fixing (augnet/centre/ambiguity_fixing.py)
    amb_prior_sigma_cyc: float = setting(300.0, unit="cycles", doc="initial SD ambiguity sigma (the state starts "
                                         "from phase minus code)")
    fix_min_elevation_deg: float = setting(
        15.0, unit="deg", doc="satellites lower at either station stay float and get no corrections: code multipath "
        "leaves their wide lane uncertain and near-equivalent integer pairs (Galileo E1/E5a (3, 4): 6 mm "
        "ionosphere-free, 0.57 m of DD ionosphere) pass the ratio test there")
    fix_ratio: float = setting(2.0, doc="LAMBDA ratio-test threshold of the partial fix",
                               source="RTKLIB pos2-arthres")
    fix_min_success_rate: float = setting(0.9999, doc="least bootstrapped success rate of the fixed subset")
    fix_min_count: int = setting(4, doc="least DD ambiguities in a partial fix")
    fix_min_count_held: int = setting(2, doc="... once this many are held: a new satellite's pair may be fixed "
                                      "on its own")
    fix_confirm_epochs: int = setting(5, unit="epochs", doc="consecutive epochs the same integer must be pinned "
                                      "before it is fixed")
    fix_confirm_epochs_sure: int = setting(2, unit="epochs", doc="... when the fixed block's success rate is at "
                                           "least fix_sure_success_rate")
    fix_sure_success_rate: float = setting(0.999999, doc="success rate that shortens the confirmation")
    search_max_sigma_cyc: float = setting(5.0, unit="cycles", doc="DD ambiguities less certain stay out of the "
                                          "integer search (they cannot be fixed yet and slow the decorrelation)")
    pinned_sigma_cyc: float = setting(0.05, unit="cycles", doc="conditioned DD ambiguity sigma at which it counts "
                                      "as pinned to its nearest integer")
    hold_sigma_cyc: float = setting(0.001, unit="cycles", doc="sigma of the hold pseudo-observation, applied once "
                                    "per newly fixed ambiguity (ambiguities have no process noise)",
                                    source="RTKLIB VAR_HOLDAMB (fix and hold)")
    release_residual_m: float = setting(0.04, unit="m", doc="a fixed DD whose post-fit phase residual stays above "
                                        "this for release_epochs is released")
    release_epochs: int = setting(3, unit="epochs", doc="epochs of a large residual before the release")
    max_gap_s: float = setting(30.0, unit="s", doc="an arc restarts after a gap longer than this")
    # --- network ionosphere hints (augnet/centre/network.py)
    iono_hints: bool = setting(
        True, doc="a satellite fixed on other baselines gives this baseline a DD ionosphere prediction (a linear "
        "model of the DD ionosphere over the network, a gradient per satellite pair)", source="decision 0104")
    iono_hints_float: bool = setting(
        True, doc="... also from the float ionosphere of baselines with no station in common where the satellite "
        "is not fixed there either", source="decision 0104")
    iono_hint_ppm_per_100km: float = setting(
        0.8, unit="ppm per 100 km", doc="the hint's error: ppm of the baseline length per 100 km between the "
        "baselines' midpoints, times hypot(M_s, M_ref)", source="decision 0104")
    iono_hint_max_distance_km: float = setting(150.0, unit="km", doc="baselines whose midpoints are farther apart "
                                               "lend no hints")
    # --- network ionosphere model (augnet/centre/network.py)
    iono_model_floor_ppm: float = setting(
        0.5, unit="ppm", doc="floor of the single-layer model's residual level (its 95 % upper bound times "
        "iono_prior_adapt); 0: no model", source="decision 0105")
    iono_model_min_dd: int = setting(8, doc="fixed DD ionospheres the network needs before it fits the model")
    iono_model_max_variance_share: float = setting(
        0.8, doc="the model's prediction replaces the day's prior only where its variance is below this share "
        "of the day's", source="decision 0105")
    # --- corrections
    residual_smoothing_s: float = setting(
        30.0, unit="s", doc="time constant of the exponential smoothing of fixed DD residuals: the geometry-free "
        "split carries ~2x the phase noise, the DD ionosphere moves by mm per minute; 0: none")


def fix_policy(cfg: BaselineConfig, min_count: int) -> FixPolicy:
    """The baseline filter's ambiguity-fixing policy: the settings' thresholds, every qualifying block searched
    (no bound) and no biased-float screening (the ionosphere pseudo-observations keep its floats unbiased)."""
    return FixPolicy(min_success_rate=cfg.fix_min_success_rate, ratio_threshold=cfg.fix_ratio, min_count=min_count)
