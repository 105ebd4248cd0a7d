"""`augnet sim record`: run a scenario faster than real time and write what every receiver produced.

Output folder:
    scenario.json      the scenario as resolved (defaults filled, ionosphere preset expanded)
    nav.rnx            RINEX 3.04 navigation: every broadcast set the receivers saw
    <id>.obs           RINEX 3.04 observations per receiver (code, phase, Doppler, C/N0, LLI)
    <id>.rtcm3         the receiver's RTCM 3 stream (1005/1006, 1033, ephemerides, MSM7), if the
                       RTCM encoders are available
    truth.csv          per epoch and receiver: ECEF truth, receiver clock; trains: track, km, speed
    atmosphere.csv     per epoch, receiver and tracked satellite: elevation, azimuth, slant TEC,
                       L1 ionosphere delay, slant troposphere, orbit error along the line of sight,
                       satellite clock error, integer ambiguities per signal

Same scenario and seed -> the same bytes in every file (no wall-clock time is written anywhere).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from augnet.gnss import time as gtime
from augnet.gnss.rinex.nav import NavHeader, write_nav
from augnet.gnss.rinex.obs import ObsHeader, empty_obs, write_obs
from stations.ionosphere import delay_m
from stations.scenario import Scenario, resolved_dict
from stations.world import EpochBlock, World

PROGRAM = "augnet sim"
RECEIVER_TYPE = "AUGNET SIMULATOR"
ANTENNA_TYPE = "AUGNET-ISOTROPIC"  # phase centre at the reference point: no PCO/PCV to model
L1_HZ = 1575.42e6


@dataclass
class RecordSummary:
    out_dir: Path
    n_epochs: int
    receivers: list[str]
    files: list[str] = field(default_factory=list)
    seconds_simulated: float = 0.0
    seconds_wall: float = 0.0


def _date_text(scenario: Scenario) -> str:
    # RINEX "date of file creation": the scenario start, so files do not depend on the wall clock
    return scenario.start.strftime("%Y%m%d %H%M%S") + " GPS"


def _obs_header(world: World, i: int) -> ObsHeader:
    sc = world.scenario
    rx = world.receivers[i]
    types = {}
    for s in sc.constellations:
        codes = sc.signals[s]
        types[s] = [f"{kind}{code}" for code in codes for kind in ("C", "L", "D", "S")]
    return ObsHeader(
        program=PROGRAM, run_by="augnet", date=_date_text(sc), marker_name=rx.id,
        marker_type="GEODETIC" if rx.kind == "station" else "NON_GEODETIC",
        observer="augnet", agency="augnet simulated world", receiver_number=str(rx.rtcm_id),
        receiver_type=RECEIVER_TYPE, receiver_version="1", antenna_type=ANTENNA_TYPE,
        approx_position_m=tuple(float(v) for v in np.round(rx.ecef[0], 4)),
        obs_types=types, signal_strength_unit="DBHZ", interval_s=sc.interval_s,
        time_system="GPS", comments=[f"scenario {sc.name} seed {sc.seed}", "simulated: truth in truth.csv"])


def _ssi(cnr):
    """RINEX signal strength digit from C/N0 (RINEX 3.04 5.7: 1 = < 12 dB-Hz ... 9 = >= 54 dB-Hz)."""
    return np.clip(np.floor(np.nan_to_num(cnr, nan=0.0) / 6.0), 1, 9).astype(np.int8)


class Recorder:
    """Collects epoch blocks and writes the output files."""

    def __init__(self, world: World, out_dir: Path, rtcm: bool = True):
        self.world = world
        self.out = Path(out_dir)
        self.out.mkdir(parents=True, exist_ok=True)
        sc = world.scenario
        self.obs = [empty_obs(_obs_header(world, i), world.t_tags, world.sats)
                    for i in range(len(world.receivers))]
        # truth and atmosphere go to disk block by block (an hour of demo is ~1 M atmosphere rows)
        self._truth_file = open(self.out / "truth.csv", "w", newline="\n")
        self._atmo_file = open(self.out / "atmosphere.csv", "w", newline="\n")
        self.truth_lines = ["gpst_s,gpst_calendar,receiver,kind,x_m,y_m,z_m,clock_s,track,km,speed_m_s"]
        k_cols = ",".join(f"N{k + 1}_cyc" for k in range(world.K))
        self.atmo_lines = ["gpst_s,receiver,sat,elevation_deg,azimuth_deg,stec_tecu,iono_l1_m,tropo_m,"
                           f"orbit_err_los_m,sat_clock_err_ns,{k_cols}"]
        self.rtcm = None
        if rtcm:
            try:
                from stations.rtcm_stream import RtcmStreams
            except ImportError:  # the RTCM encoders are not in this tree yet
                self.rtcm = None
            else:
                self.rtcm = RtcmStreams(world)
        self.sc = sc

    def add(self, blk: EpochBlock) -> None:
        w = self.world
        e_idx = blk.epoch_index
        for i, rx in enumerate(w.receivers):
            data = self.obs[i]
            for sysl in w.scenario.constellations:
                cols = np.flatnonzero(w.sat_system == sysl)
                for k, code in enumerate(w.scenario.signals[sysl]):
                    for kind, arr in (("C", blk.pseudorange_m), ("L", blk.phase_cyc),
                                      ("D", blk.doppler_hz), ("S", blk.cnr_dbhz)):
                        name = f"{kind}{code}"
                        data.obs[name][np.ix_(e_idx, cols)] = arr[:, i, cols, k]
                    data.lli[f"L{code}"][np.ix_(e_idx, cols)] = blk.lli[:, i, cols, k]
                    ssi = np.where(blk.observed[:, i, cols, k], _ssi(blk.cnr_dbhz[:, i, cols, k]), 0)
                    data.ssi[f"C{code}"][np.ix_(e_idx, cols)] = ssi
                    data.ssi[f"L{code}"][np.ix_(e_idx, cols)] = ssi
        self._truth(blk)
        self._atmosphere(blk)
        self._flush()
        if self.rtcm is not None:
            self.rtcm.add(blk)

    def _truth(self, blk: EpochBlock) -> None:
        w = self.world
        for e, t in enumerate(blk.t_gpst):
            y, mo, d, h, mi, s = gtime.to_calendar(float(t), decimals=3)
            stamp = f"{y:04d}-{mo:02d}-{d:02d}T{h:02d}:{mi:02d}:{s:06.3f}"
            for i, rx in enumerate(w.receivers):
                x = blk.rx_ecef[e, i]
                ep = blk.epoch_index[e]
                if rx.kind == "train":
                    extra = f"{rx.track_id},{rx.km[ep]:.6f},{rx.speed_m_s[ep]:.4f}"
                else:
                    extra = ",,"
                self.truth_lines.append(f"{t:.3f},{stamp},{rx.id},{rx.kind},{x[0]:.4f},{x[1]:.4f},{x[2]:.4f},"
                                        f"{blk.rx_clock_s[e, i]:.12e},{extra}")

    def _atmosphere(self, blk: EpochBlock) -> None:
        w = self.world
        tracked = blk.observed.any(-1)  # (E, R, N)
        e_i, r_i, n_i = np.nonzero(tracked)
        el = np.degrees(blk.elevation_rad[e_i, r_i, n_i])
        az = np.degrees(blk.azimuth_rad[e_i, r_i, n_i])
        stec = blk.stec_tecu[e_i, r_i, n_i]
        iono = delay_m(stec, L1_HZ)
        tropo = blk.tropo_m[e_i, r_i, n_i]
        orb = blk.orbit_error_range_m[e_i, r_i, n_i]
        clk = blk.sat_clock_error_s[e_i, r_i, n_i] * 1e9
        amb = blk.ambiguity_cyc[e_i, r_i, n_i]
        ids = w.receiver_ids
        for j in range(len(e_i)):
            ambs = ",".join("" if np.isnan(a) else str(int(a)) for a in amb[j])
            self.atmo_lines.append(
                f"{blk.t_gpst[e_i[j]]:.3f},{ids[r_i[j]]},{w.sats[n_i[j]]},{el[j]:.4f},{az[j]:.4f},"
                f"{stec[j]:.5f},{iono[j]:.5f},{tropo[j]:.5f},{orb[j]:.5f},{clk[j]:.5f},{ambs}")

    def _flush(self) -> None:
        if self.truth_lines:
            self._truth_file.write("\n".join(self.truth_lines) + "\n")
            self.truth_lines = []
        if self.atmo_lines:
            self._atmo_file.write("\n".join(self.atmo_lines) + "\n")
            self.atmo_lines = []

    def finish(self) -> list[str]:
        w = self.world
        files = []
        (self.out / "scenario.json").write_text(json.dumps(resolved_dict(self.sc), indent=2, sort_keys=True) + "\n")
        files.append("scenario.json")
        write_nav(self.out / "nav.rnx", w.ephemerides,
                  NavHeader(program=PROGRAM, run_by="augnet", date=_date_text(self.sc), leap_seconds=18,
                            comments=[f"scenario {self.sc.name}: "
                                      + ("nominal augnet constellation" if w.nominal else "given nav file")]))
        files.append("nav.rnx")
        for i, rx in enumerate(w.receivers):
            write_obs(self.out / f"{rx.id}.obs", self.obs[i])
            files.append(f"{rx.id}.obs")
        self._flush()
        self._truth_file.close()
        self._atmo_file.close()
        files += ["truth.csv", "atmosphere.csv"]
        if self.rtcm is not None:
            files += self.rtcm.write(self.out)
        return files


def record(scenario: Scenario, out_dir: str | Path, nav_ephemerides=None, rtcm: bool = True) -> RecordSummary:
    """Simulate the whole scenario and write the recording folder."""
    import time

    t_wall = time.perf_counter()
    world = World(scenario, nav_ephemerides)
    rec = Recorder(world, Path(out_dir), rtcm=rtcm)
    for blk in world.epochs():
        rec.add(blk)
    files = rec.finish()
    return RecordSummary(Path(out_dir), world.n_epochs, world.receiver_ids, files,
                         scenario.duration_s, time.perf_counter() - t_wall)
