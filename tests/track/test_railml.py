"""railML 2.x subset import of the hand-written test line; malformed files refused naming the element."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from augnet.track.railml import topology_from_railml
from augnet.track.topology import Topology, TopologyError
from augnet.track.topology_file import import_railml, load_topology, save_geojson, save_topology

LINE = Path(__file__).with_name("two_stations.railml")


@pytest.fixture(scope="module")
def text() -> str:
    return LINE.read_text(encoding="utf-8")


@pytest.fixture(scope="module")
def topo() -> Topology:
    return import_railml(LINE)


def refused(text: str) -> TopologyError:
    with pytest.raises(TopologyError) as exc:
        topology_from_railml(text.encode())
    return exc.value


def test_import_the_test_line(topo):
    assert len(topo.edges) == 14 and len(topo.turnouts) == 4
    assert topo.edges_of_track("1") == ["t1a.0", "t1a.1", "t1b", "t1c.0", "t1c.1", "t1c.2"]
    assert topo.edges["x12"].kind == "crossover"
    assert [topo.edges[e].kind for e in ("l3a", "l3b", "l3c")] == ["loop", "platform", "loop"]
    stations = {p.name for p in topo.points.values() if p.kind == "station"}
    assert stations == {"Alpha", "Beta"}
    assert topo.edges["l3b"].station == "Beta" and topo.edges["t1a.0"].station == "Alpha"
    a1 = topo.turnouts["swA1"]
    assert (a1.toe, a1.straight, a1.diverging, a1.course) == ("t1a.0", "t1a.1", "x12", "left")
    a2 = topo.turnouts["swA2"]  # incoming: the toe is on the far side of the branch
    assert (a2.toe, a2.straight, a2.diverging) == ("t2a.1", "t2a.0", "x12")
    b2 = topo.turnouts["swB2"]
    assert (b2.toe, b2.straight, b2.diverging) == ("t1c.2", "t1c.1", "l3c")
    # frog where the centre lines are a gauge apart: 1.435 m at 4.6 m over 60 m -> 18.8 m
    assert a1.frog_m == pytest.approx(1.435 / 4.6 * 60.176, abs=0.2)
    assert topo.turnouts["swB1"].frog_m == pytest.approx(1.435 / 4.6 * 100.106, abs=0.2)
    kinds = sorted(p.kind for p in topo.points.values())
    assert kinds.count("balise_group") == 4 and kinds.count("signal") == 2 and kinds.count("platform_end") == 2
    assert topo.points["pe3.end"].km == pytest.approx(8.75) and topo.points["bg1"].direction == "up"
    assert {s.id for s in topo.sections.values()} == {"sb1", "sb2", "sb3", "sb4"}
    assert topo.sections["sb2"].edge == "t1c.0" and topo.sections["sb2"].km == pytest.approx(7.0)


def test_json_round_trip_is_equal(topo, tmp_path):
    d = topo.to_dict()
    again = Topology.from_dict(json.loads(json.dumps(d)))
    assert again.to_dict() == d
    save_topology(topo, tmp_path / "line.json")
    assert load_topology(tmp_path / "line.json").to_dict() == d


def test_geojson_export_structure(topo, tmp_path):
    save_geojson(topo, tmp_path / "line.geojson")
    g = json.loads((tmp_path / "line.geojson").read_text())
    assert g["type"] == "FeatureCollection"
    by: dict[str, list] = {}
    for f in g["features"]:
        assert f["type"] == "Feature" and set(f) == {"type", "geometry", "properties"}
        by.setdefault(f["properties"]["feature"], []).append(f)
        geom = f["geometry"]
        coords = geom["coordinates"] if geom["type"] == "LineString" else [geom["coordinates"]]
        assert geom["type"] in ("LineString", "Point") and len(coords) >= (2 if geom["type"] == "LineString" else 1)
        for lon, lat, h in coords:  # RFC 7946 order: longitude first; points on chords sag below 100 m
            assert 8.99 < lon < 9.13 and 44.99 < lat < 45.01 and h == pytest.approx(100.0, abs=0.5)
    assert len(by["track"]) == 14 and len(by["switch"]) == 4 and len(by["balise_group"]) == 4
    assert all(f["geometry"]["type"] == "LineString" for f in by["track"])
    sw = next(f for f in by["switch"] if f["properties"]["id"] == "swA1")
    assert sw["properties"]["diverging"] == "x12"


def test_missing_ref_is_refused_naming_the_connection(text):
    e = refused(text.replace('ref="cA1"', 'ref="nowhere"'))
    assert e.element == "<connection id='cx_b'>" and "missing ref" in e.reason and "nowhere" in e.reason


def test_one_sided_ref_is_refused(text):
    e = refused(text.replace('<connection id="c1b_b" ref="c1a_e"/>', '<connection id="c1b_b" ref="c2a_e"/>'))
    assert "refers back" in str(e)


def test_unknown_switch_leg_is_refused(text):
    e = refused(text.replace('course="right" orientation="outgoing"', 'course="sideways" orientation="outgoing"'))
    assert e.element == "<connection id='cB1'>" and "unknown switch leg" in e.reason
    e = refused(text.replace('course="right" orientation="outgoing"', 'course="straight" orientation="outgoing"'))
    assert e.element == "<switch id='swB1'>" and "trackContinueCourse" in e.reason


def test_doctype_with_an_entity_is_refused(text):
    body = text.split("?>", 1)[1]
    for doctype in ('<!DOCTYPE railml [<!ENTITY boom "boom">]>',
                    '<!DOCTYPE railml [<!ENTITY xxe SYSTEM "file:///etc/passwd">]>',
                    '<!DOCTYPE railml SYSTEM "http://example.invalid/railml.dtd">'):
        e = refused('<?xml version="1.0"?>' + doctype + body.replace('name="A1"', 'name="&boom;"'))
        assert e.element == "DOCTYPE" and "refused" in e.reason


def test_not_xml_at_all_is_refused():
    for data in ("this is not XML", '{"format": "augnet-topology/1"}', "<railml><infrastructure></railml>", ""):
        e = refused(data)
        assert e.element == "file" and e.reason.startswith("not XML")


def test_other_root_or_namespace_is_refused(text):
    e = refused(text.replace("http://www.railml.org/schemas/2013", "http://www.railml.org/schemas/3.1"))
    assert "not a railML 2.x" in e.reason


def test_geometry_gap_is_refused_naming_the_edge(text):
    # the crossover's end 11 m east of switch A2
    e = refused(text.replace('<geoCoord coord="45.000039678 9.019784899 100.0"/>\n            <connection id="cx_e"',
                             '<geoCoord coord="45.000039678 9.019924899 100.0"/>\n            <connection id="cx_e"'))
    assert e.element == "edge x12" and "geometry gap" in e.reason and "swA2" in e.reason


def test_decreasing_mileage_is_refused(text):
    e = refused(text.replace('<trackEnd id="t1b_e" pos="4000" absPos="7000">',
                             '<trackEnd id="t1b_e" pos="4000" absPos="2000">'))
    assert e.element == "<track id='t1b'>" and "chainage not increasing" in e.reason


def test_bad_numbers_and_missing_geometry_are_refused(text):
    e = refused(text.replace('<switch id="swB2" name="B2" pos="2000"', '<switch id="swB2" name="B2" pos="two"'))
    assert e.element == "<switch id='swB2'>" and "not a number" in e.reason
    e = refused(text.replace('<geoCoord coord="44.999929580 9.126825980 100.0"/>', ""))
    assert e.element == "<trackEnd id='t1c_e'>" and "geoCoord" in e.reason
    e = refused(text.replace('<ocp id="ocpB" name="Beta"/>', ""))
    assert e.element == "<crossSection id='cs2'>" and "ocpB" in e.reason


def test_damaged_files_import_or_are_refused_never_crash(text):
    """Truncated at every 37th byte, or with any one attribute removed: a Topology or a
    TopologyError, nothing else."""
    import re

    cases = [text[:n] for n in range(0, len(text), 37)]
    attrs = list(re.finditer(r'\s[A-Za-z]+="[^"]*"', text))
    cases += [text[:m.start()] + text[m.end():] for m in attrs]
    refusals = 0
    for case in cases:
        try:
            topology_from_railml(case.encode())
        except TopologyError:
            refusals += 1
    assert refusals >= len(cases) // 2  # every truncation is refused at least


def test_an_id_naming_two_nodes_is_refused(text):
    e = refused(text.replace('<bufferStop id="bs1e"/>', '<bufferStop id="swB2"/>'))
    assert "swB2" in e.element and "duplicate id" in e.reason
