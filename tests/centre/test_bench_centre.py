"""`augnet bench centre`: network figures per size, in milliseconds and in yardstick units (issue 17)."""

import json
import shutil

from augnet.bench import centre


def test_network_bench_prints_sizes_and_yardstick(capsys):
    centre.main(["--stations", "6", "--epochs", "3", "--network-only", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert out["network_6_stations_baselines"] == 7
    assert out["network_6_stations_ms_per_epoch"] > 0
    if shutil.which("rnx2rtkp") and centre.yardstick_ms() is not None:
        y = out["yardstick_rnx2rtkp_ms_per_epoch"]
        assert y > 0
        assert abs(out["network_6_stations_yardsticks"] - out["network_6_stations_ms_per_epoch"] / y) < 0.1


def test_larger_networks_are_parallel_lines():
    world = centre._world(2 * centre.STATIONS_PER_LINE + 1, 1)
    lat_lon = [(s.lat_deg, s.lon_deg) for s in world.scenario.stations]
    assert all(abs(lat) < 60.0 for lat, _ in lat_lon)  # on the Earth, not wrapped past the pole
    first, second = lat_lon[0], lat_lon[centre.STATIONS_PER_LINE]
    assert first[0] == second[0] and abs(second[1] - first[1] - centre.LINE_SPACING_DEG) < 1e-12
