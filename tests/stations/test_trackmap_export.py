"""The exported track database is the line the simulated trains really run on."""

import numpy as np

from augnet.onboard.trackmap import FORMAT, TrackDatabase
from stations import trackmap_export
from stations.scenario import load_scenario
from stations.world import World


def test_format_tag_matches_the_onboard_reader():
    assert trackmap_export.FORMAT == FORMAT


def test_true_train_positions_lie_on_their_exported_track():
    sc = load_scenario("demo").model_copy(update={"duration_s": 30})
    world = World(sc)
    db = TrackDatabase.from_dict(trackmap_export.track_database(sc, world.track))
    trains = [rx for rx in world.receivers if rx.kind == "train"]
    assert len(trains) == 2
    for rx in trains:
        for e in range(0, len(rx.ecef), 5):
            m = db.match(rx.ecef[e])
            assert m.track == rx.track_id
            # the antenna is above the rail: horizontal offset from the polyline only mm, km exact
            assert abs(m.cross_m) < 0.01, (rx.id, e, m)
            assert abs(m.km - rx.km[e]) < 1e-3, (rx.id, e, m.km, rx.km[e])


def test_virtual_balises_on_every_main_track_at_the_configured_spacing():
    sc = load_scenario("demo")
    d = trackmap_export.track_database(sc, balise_spacing_km=10.0)
    by_track = {}
    for b in d["balises"]:
        by_track.setdefault(b["track"], []).append(b["km"])
    assert set(by_track) == {"L1-1", "L1-2"}
    for kms in by_track.values():
        assert np.allclose(np.diff(kms), 10.0)
        assert kms[0] >= trackmap_export.BALISE_MARGIN_KM
    assert len({b["id"] for b in d["balises"]}) == len(d["balises"])
    assert trackmap_export.track_database(sc, balise_spacing_km=0)["balises"] == []
