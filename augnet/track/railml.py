"""railML 2.x infrastructure subset -> `Topology`.

Read (element and attribute names as in railML 2.2, namespace http://www.railml.org/schemas/2013;
2.3 and 2.5 share the names in this subset):

    railml/infrastructure[@id, @name]
      operationControlPoints/ocp[@id, @name]                           stations
      tracks/track[@id, @name, @type]
        trackTopology/trackBegin|trackEnd[@id, @pos, @absPos]
            geoCoord[@coord="lat lon [h]", @epsgCode]                   WGS 84 only
            connection[@id, @ref] | bufferStop[@id] | openEnd[@id] | macroscopicNode[@id]
        trackTopology/connections/switch[@id, @name, @pos, @absPos, @trackContinueCourse]
            geoCoord, connection[@id, @ref, @course, @orientation]      one branch per switch
        trackTopology/crossSections/crossSection[@id, @name, @pos, @ocpRef]
        trackElements/platformEdges/platformEdge[@id, @name, @pos, @length]
        ocsElements/balises/balise[@id, @name, @pos, @dir]
        ocsElements/signals/signal[@id, @name, @pos, @dir]
        ocsElements/trainDetectionElements/trackCircuitBorder[@id, @name, @pos]   section boundaries

`pos` is metres along the track from its trackBegin; `absPos` the line's mileage [m] (chainage; where
absent, pos).  A track's geometry is the polyline through the geoCoords of its trackBegin, switches and
trackEnd in pos order.  A railML file is untrusted input: the parser refuses any DOCTYPE (so no entity
of any kind, internal or external, is ever declared or expanded) and files over MAX_RAILML_BYTES.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from xml.parsers import expat

import numpy as np

from augnet.gnss.geometry import geodetic_deg_to_ecef
from augnet.track.topology import (
    Edge, Node, PointOfInterest, SectionBoundary, Topology, TopologyError, Turnout, frog_distance_m,
)

# railML 2.x namespaces (2.2: schemas/2013, 2.3: schemas/2016, 2.5: schemas/2021, as in the
# schemaLocation of railML.org's published schemas).
RAILML2_NAMESPACES = {
    "http://www.railml.org/schemas/2013": "2.2",
    "http://www.railml.org/schemas/2016": "2.3",
    "https://www.railml.org/schemas/2021": "2.5",
}
# A national network's infrastructure file is tens of MB (railML.org's examples); 256 MiB refuses a
# runaway input before it is parsed.
MAX_RAILML_BYTES = 256 * 1024 * 1024
# geoCoord@epsgCode values read as WGS 84 geographic (lat, lon [, ellipsoidal h]); absent = WGS 84.
WGS84_EPSG_CODES = {"", "4326", "4979", "EPSG:4326", "EPSG:4979", "urn:ogc:def:crs:EPSG::4326",
                    "urn:ogc:def:crs:EPSG::4979"}
TRACK_TYPE_KIND = {"mainTrack": "main", "secondaryTrack": "loop", "stationTrack": "loop",
                   "sidingTrack": "siding", "connectingTrack": "connecting", "": "main"}
POS_TOLERANCE_M = 1e-6


class _Refused(Exception):
    """Raised inside an expat handler; carries the TopologyError out of the parser."""


def parse_railml_xml(data: bytes) -> ET.Element:
    """Namespace-aware parse with no DOCTYPE, no entities; tags as "{namespace}local"."""
    if len(data) > MAX_RAILML_BYTES:
        raise TopologyError("file", f"larger than {MAX_RAILML_BYTES} bytes")
    builder = ET.TreeBuilder()
    p = expat.ParserCreate(namespace_separator="}")
    p.SetParamEntityParsing(expat.XML_PARAM_ENTITY_PARSING_NEVER)

    def tag(name: str) -> str:
        return "{" + name if "}" in name else name

    def refuse(what: str):
        def handler(*args):
            raise _Refused(TopologyError(what, "refused: a railML file needs no DOCTYPE or entities, and they "
                                               "can expand or fetch content (untrusted input)"))
        return handler

    p.StartElementHandler = lambda name, attrs: builder.start(tag(name), {tag(k): v for k, v in attrs.items()})
    p.EndElementHandler = lambda name: builder.end(tag(name))
    p.CharacterDataHandler = builder.data
    p.StartDoctypeDeclHandler = refuse("DOCTYPE")
    p.EntityDeclHandler = refuse("ENTITY")
    p.UnparsedEntityDeclHandler = refuse("ENTITY")
    p.ExternalEntityRefHandler = refuse("external entity")
    try:
        p.Parse(data, True)
    except _Refused as exc:
        raise exc.args[0] from None
    except expat.ExpatError as exc:
        raise TopologyError("file", f"not XML: {expat.errors.messages[exc.code]} at line {exc.lineno}, "
                                    f"column {exc.offset}") from None
    return builder.close()


def topology_from_railml(data: bytes) -> Topology:
    root = parse_railml_xml(data)
    ns = root.tag[1:].split("}")[0] if root.tag.startswith("{") else ""
    if root.tag.split("}")[-1] != "railml" or ns not in RAILML2_NAMESPACES:
        raise TopologyError(f"<{root.tag}>", f"root is not a railML 2.x <railml> element (namespace {ns!r}; "
                                             f"read: {', '.join(RAILML2_NAMESPACES)})")
    return _Importer(ns).run(root)


@dataclass
class _Conn:
    id: str
    ref: str
    owner: str  # "begin" / "end" / "switch"
    track: str
    switch: str = ""
    course: str = ""
    orientation: str = ""
    where: str = ""


@dataclass
class _Track:
    id: str
    name: str
    kind: str
    el: ET.Element
    begin_pos: float = 0.0
    end_pos: float = 0.0
    geo_pos: list[float] = field(default_factory=list)
    geo_llh: list[tuple[float, float, float]] = field(default_factory=list)
    abs_pos: list[tuple[float, float]] = field(default_factory=list)  # (pos m, absPos m)
    switches: list[tuple[float, str]] = field(default_factory=list)  # (pos m, switch id)
    edges: list[tuple[float, float, str]] = field(default_factory=list)  # (pos from, pos to, edge id)


class _Importer:
    def __init__(self, ns: str):
        self.ns = ns

    def q(self, path: str) -> str:
        return "/".join("{%s}%s" % (self.ns, p) for p in path.split("/"))

    def run(self, root: ET.Element) -> Topology:
        infra = root.find(self.q("infrastructure"))
        if infra is None:
            raise TopologyError("<railml>", "has no <infrastructure>")
        ocps = {o.get("id", ""): o.get("name", o.get("id", ""))
                for o in infra.iterfind(self.q("operationControlPoints/ocp"))}
        track_els = infra.findall(self.q("tracks/track"))
        if not track_els:
            raise TopologyError("<infrastructure>", "has no <tracks>/<track>")
        self.tracks: dict[str, _Track] = {}
        self.conns: dict[str, _Conn] = {}
        self.end_kind: dict[tuple[str, str], tuple[str, str]] = {}  # (track, side) -> (node kind, node id)
        self.switch_pos: dict[str, tuple[str, float, ET.Element]] = {}
        for tel in track_els:
            self._read_track(tel)
        nodes, edges, turnouts = self._build()
        points, sections = [], []
        for t in self.tracks.values():
            for el, kind in ((self.q("ocsElements/balises/balise"), "balise_group"),
                             (self.q("ocsElements/signals/signal"), "signal")):
                for b in t.el.iterfind(el):
                    eid, km = self._locate(t, b)
                    points.append(PointOfInterest(_id(b), kind, eid, km, b.get("name", ""), _dir(b)))
            for pe in t.el.iterfind(self.q("trackElements/platformEdges/platformEdge")):
                pos, length = _num(pe, "pos"), _num(pe, "length")
                for suffix, p in (("begin", pos), ("end", pos + length)):
                    eid, km = self._locate(t, pe, p)
                    points.append(PointOfInterest(f"{_id(pe)}.{suffix}", "platform_end", eid, km, pe.get("name", "")))
            for cs in t.el.iterfind(self.q("trackTopology/crossSections/crossSection")):
                eid, km = self._locate(t, cs)
                ocp = cs.get("ocpRef", "")
                if ocp not in ocps:
                    raise TopologyError(_name(cs), f"ocpRef {ocp!r} names no <ocp>")
                points.append(PointOfInterest(_id(cs), "station", eid, km, ocps[ocp]))
                edges[eid] = _with_station(edges[eid], ocps[ocp])
            for tcb in t.el.iterfind(self.q("ocsElements/trainDetectionElements/trackCircuitBorder")):
                eid, km = self._locate(t, tcb)
                sections.append(SectionBoundary(_id(tcb), eid, km, tcb.get("name", "")))
        for t in self.tracks.values():
            # a station track with a platform edge is a platform track
            if t.kind == "loop" and t.el.find(self.q("trackElements/platformEdges/platformEdge")) is not None:
                for _, _, eid in t.edges:
                    edges[eid] = _with_kind(edges[eid], "platform")
        return Topology(infra.get("name", infra.get("id", "")), nodes.values(), edges.values(), turnouts, points,
                        sections)

    # ------------------------------------------------------------------------------------------

    def _read_track(self, tel: ET.Element) -> None:
        tid = _id(tel)
        if tid in self.tracks:
            raise TopologyError(_name(tel), "duplicate track id")
        ttype = tel.get("type", "")
        if ttype not in TRACK_TYPE_KIND:
            known = ", ".join(k for k in TRACK_TYPE_KIND if k)
            raise TopologyError(_name(tel), f"type {ttype!r} is not one of {known}")
        t = _Track(tid, tel.get("name", ""), TRACK_TYPE_KIND[ttype], tel)
        topo = tel.find(self.q("trackTopology"))
        if topo is None:
            raise TopologyError(_name(tel), "has no <trackTopology>")
        for side in ("begin", "end"):
            el = topo.find(self.q("track" + side.capitalize()))
            if el is None:
                raise TopologyError(_name(tel), f"has no <track{side.capitalize()}>")
            pos = _num(el, "pos")
            setattr(t, f"{side}_pos", pos)
            self._read_point(t, el, pos, required_geo=True)
            self._read_end(t, side, el)
        if not t.end_pos > t.begin_pos:
            raise TopologyError(_name(tel), f"trackEnd pos {t.end_pos} is not after trackBegin pos {t.begin_pos}")
        for sw in topo.iterfind(self.q("connections/switch")):
            sid = _id(sw)
            if sid in self.switch_pos:
                raise TopologyError(_name(sw), "duplicate switch id")
            pos = _num(sw, "pos")
            if not t.begin_pos + POS_TOLERANCE_M < pos < t.end_pos - POS_TOLERANCE_M:
                raise TopologyError(_name(sw), f"pos {pos} is not inside its track {tid} ({t.begin_pos}-{t.end_pos}); "
                                               "the subset reads switches inside a track")
            self._read_point(t, sw, pos, required_geo=False)
            cs = sw.findall(self.q("connection"))
            if len(cs) != 1:
                raise TopologyError(_name(sw), f"{len(cs)} <connection> elements; a simple switch has one (its branch)")
            c = cs[0]
            self._add_conn(_Conn(_id(c), c.get("ref", ""), "switch", tid, sid, c.get("course", ""),
                                 c.get("orientation", ""), _name(c)))
            self.switch_pos[sid] = (tid, pos, sw)
            t.switches.append((pos, sid))
        t.switches.sort()
        if len({p for p, _ in t.switches}) != len(t.switches):
            raise TopologyError(_name(tel), "two switches at the same pos")
        order = np.argsort(t.geo_pos, kind="stable")
        t.geo_pos = [t.geo_pos[i] for i in order]
        t.geo_llh = [t.geo_llh[i] for i in order]
        if np.any(np.diff(t.geo_pos) <= 0):
            raise TopologyError(_name(tel), "two geoCoords at the same pos")
        t.abs_pos.sort()
        if np.any(np.diff([a for _, a in t.abs_pos]) <= 0):
            raise TopologyError(_name(tel), f"chainage not increasing: absPos {[a for _, a in t.abs_pos]} by pos")
        self.tracks[tid] = t

    def _read_point(self, t: _Track, el: ET.Element, pos: float, required_geo: bool) -> None:
        if el.get("absPos") is not None:
            t.abs_pos.append((pos, _num(el, "absPos")))
        g = el.find(self.q("geoCoord"))
        if g is None:
            if required_geo:
                raise TopologyError(_name(el), "has no <geoCoord>: the track's geometry needs its ends")
            return
        epsg = g.get("epsgCode", "").strip()
        if epsg not in WGS84_EPSG_CODES:
            raise TopologyError(_name(el), f"geoCoord epsgCode {epsg!r}: only WGS 84 (EPSG 4326/4979) is read")
        try:
            v = [float(x) for x in g.get("coord", "").split()]
        except ValueError:
            v = []
        if len(v) not in (2, 3) or not np.all(np.isfinite(v)) or abs(v[0]) > 90 or abs(v[1]) > 180:
            raise TopologyError(_name(el), f"geoCoord coord {g.get('coord')!r} is not 'lat lon [h]'")
        t.geo_pos.append(pos)
        t.geo_llh.append((v[0], v[1], v[2] if len(v) == 3 else 0.0))

    def _read_end(self, t: _Track, side: str, el: ET.Element) -> None:
        kids = [k for k in el if k.tag.split("}")[-1] in ("connection", "bufferStop", "openEnd", "macroscopicNode")]
        if len(kids) != 1:
            raise TopologyError(_name(el), "needs exactly one of connection, bufferStop, openEnd, macroscopicNode")
        k = kids[0]
        local = k.tag.split("}")[-1]
        if local == "connection":
            self._add_conn(_Conn(_id(k), k.get("ref", ""), side, t.id, where=_name(k)))
        else:
            self.end_kind[(t.id, side)] = ("buffer_stop" if local == "bufferStop" else "open_end",
                                           k.get("id") or f"{t.id}.{side}")

    def _add_conn(self, c: _Conn) -> None:
        if c.id in self.conns:
            raise TopologyError(c.where, "duplicate connection id")
        self.conns[c.id] = c

    # ------------------------------------------------------------------------------------------

    def _km(self, t: _Track, pos: float) -> float:
        if not t.abs_pos:
            return pos / 1000.0
        p = np.array([a for a, _ in t.abs_pos])
        a = np.array([b for _, b in t.abs_pos])
        if len(p) == 1:
            return float(a[0] + (pos - p[0])) / 1000.0
        if pos < p[0]:
            return float(a[0] - (p[0] - pos)) / 1000.0
        if pos > p[-1]:
            return float(a[-1] + (pos - p[-1])) / 1000.0
        return float(np.interp(pos, p, a)) / 1000.0

    def _llh(self, t: _Track, pos: float) -> tuple[float, float, float]:
        g = np.array(t.geo_llh)
        return tuple(float(np.interp(pos, t.geo_pos, g[:, i])) for i in range(3))

    def _build(self):
        for c in self.conns.values():  # missing refs first: the one-sided pair they leave is a consequence
            if c.ref not in self.conns:
                raise TopologyError(c.where, f"missing ref: {c.ref!r} names no connection")
        for c in self.conns.values():
            other = self.conns[c.ref]
            if other.ref != c.id:
                raise TopologyError(c.where, f"ref {c.ref!r} names {other.where}, which refers back to {other.ref!r}")
            if c.owner == "switch" and other.owner == "switch":
                raise TopologyError(c.where, "joins two switches directly; the subset needs a track between them")
        nodes: dict[str, Node] = {}
        edges: dict[str, Edge] = {}
        for t in self.tracks.values():
            cuts = [t.begin_pos] + [p for p, _ in t.switches] + [t.end_pos]
            for i, (p0, p1) in enumerate(zip(cuts, cuts[1:])):
                eid = t.id if len(cuts) == 2 else f"{t.id}.{i}"
                inner = [(p, llh) for p, llh in zip(t.geo_pos, t.geo_llh) if p0 < p < p1]
                pos = [p0] + [p for p, _ in inner] + [p1]
                llh = [self._llh(t, p0)] + [v for _, v in inner] + [self._llh(t, p1)]
                begin = t.switches[i - 1][1] if i > 0 else self._end_node(t, "begin", nodes)
                end = t.switches[i][1] if i < len(t.switches) else self._end_node(t, "end", nodes)
                edges[eid] = Edge(eid, t.name or t.id, t.kind, begin, end, np.array(llh, dtype=float),
                                  np.array([self._km(t, p) for p in pos]))
                t.edges.append((p0, p1, eid))
            for p, sid in t.switches:
                if sid in nodes:  # railML ids are xs:ID, unique in the document
                    raise TopologyError(f"<switch id={sid!r}>", "id also names another node")
                nodes[sid] = Node(sid, "switch", self._llh(t, p))
        turnouts = [self._turnout(sid, edges) for sid in self.switch_pos]
        for e in list(edges.values()):
            if e.kind == "connecting" and all(n in self.switch_pos and self.tracks[self.switch_pos[n][0]].kind == "main"
                                              for n in (e.begin, e.end)):
                edges[e.id] = _with_kind(e, "crossover")
        return nodes, edges, turnouts

    def _end_node(self, t: _Track, side: str, nodes: dict[str, Node]) -> str:
        pos = t.begin_pos if side == "begin" else t.end_pos
        if (t.id, side) in self.end_kind:
            kind, nid = self.end_kind[(t.id, side)]
            if nid in nodes or nid in self.switch_pos:
                raise TopologyError(f"<{kind}> {nid}", "duplicate id")
            nodes[nid] = Node(nid, kind, self._llh(t, pos))
            return nid
        c = next(c for c in self.conns.values() if c.track == t.id and c.owner == side)
        other = self.conns[c.ref]
        if other.owner == "switch":
            return other.switch
        nid = min(c.id, other.id)  # one joint node for the pair, named by the smaller connection id
        if nid not in nodes:
            nodes[nid] = Node(nid, "joint", self._llh(t, pos))
        return nid

    def _turnout(self, sid: str, edges: dict[str, Edge]) -> Turnout:
        tid, pos, sw = self.switch_pos[sid]
        t = self.tracks[tid]
        before = next(eid for p0, p1, eid in t.edges if abs(p1 - pos) <= POS_TOLERANCE_M)
        after = next(eid for p0, p1, eid in t.edges if abs(p0 - pos) <= POS_TOLERANCE_M)
        c = next(c for c in self.conns.values() if c.switch == sid)
        other = self.conns[c.ref]
        bt = self.tracks[other.track]
        branch = bt.edges[0][2] if other.owner == "begin" else bt.edges[-1][2]
        if c.orientation == "outgoing":
            toe, cont = before, after
        elif c.orientation == "incoming":
            toe, cont = after, before
        else:
            raise TopologyError(c.where, f"orientation {c.orientation!r}: the subset reads outgoing or incoming")
        if c.course in ("left", "right"):
            straight, diverging, course = cont, branch, c.course
        elif c.course == "straight":
            course = sw.get("trackContinueCourse", "")
            if course not in ("left", "right"):
                raise TopologyError(_name(sw), "unknown switch leg: branch course straight, so trackContinueCourse "
                                               f"must be left or right, not {course!r}")
            straight, diverging = branch, cont
        else:
            raise TopologyError(c.where, f"unknown switch leg: course {c.course!r} is not left, right or straight")
        e_st, e_dv = edges[straight], edges[diverging]
        x_st = geodetic_deg_to_ecef(e_st.points_llh[:, 0], e_st.points_llh[:, 1], e_st.points_llh[:, 2])
        x_dv = geodetic_deg_to_ecef(e_dv.points_llh[:, 0], e_dv.points_llh[:, 1], e_dv.points_llh[:, 2])
        frog = frog_distance_m(x_st, x_dv, diverging_from_switch=(e_dv.begin == sid))
        if frog is None:
            raise TopologyError(_name(sw), f"the diverging leg {diverging} never gets a gauge away from the straight "
                                           f"leg {straight}: no frog (geometry of the legs)")
        return Turnout(sid, toe, straight, diverging, course, frog, sw.get("name", ""))

    def _locate(self, t: _Track, el: ET.Element, pos: float | None = None) -> tuple[str, float]:
        pos = _num(el, "pos") if pos is None else pos
        for p0, p1, eid in t.edges:
            if p0 - POS_TOLERANCE_M <= pos <= p1 + POS_TOLERANCE_M:
                return eid, self._km(t, pos)
        raise TopologyError(_name(el), f"pos {pos} is outside its track {t.id} ({t.begin_pos}-{t.end_pos})")


def _id(el: ET.Element) -> str:
    v = el.get("id")
    if not v:
        raise TopologyError(_name(el), "missing id")
    return v


def _name(el: ET.Element) -> str:
    local = el.tag.split("}")[-1]
    return f"<{local} id={el.get('id')!r}>" if el.get("id") else f"<{local}>"


def _num(el: ET.Element, attr: str) -> float:
    v = el.get(attr)
    if v is None:
        raise TopologyError(_name(el), f"missing attribute {attr}")
    try:
        x = float(v)
    except ValueError:
        raise TopologyError(_name(el), f"attribute {attr}={v!r} is not a number") from None
    if not np.isfinite(x):
        raise TopologyError(_name(el), f"attribute {attr}={v!r} is not finite")
    return x


def _dir(el: ET.Element) -> str:
    d = el.get("dir", "")
    return d if d in ("up", "down") else ""


def _with_station(e: Edge, station: str) -> Edge:
    return Edge(e.id, e.track, e.kind, e.begin, e.end, e.points_llh, e.km, station, e.name)


def _with_kind(e: Edge, kind: str) -> Edge:
    return Edge(e.id, e.track, kind, e.begin, e.end, e.points_llh, e.km, e.station, e.name)
