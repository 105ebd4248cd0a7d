"""Network status: baselines (length, ambiguity state, residual quality), station counts, the centre's summary
(epoch, master station, interpolation model, quality flag, excluded satellites, correction age), the line."""

from __future__ import annotations

from fastapi import APIRouter

from augnet.console.deps import Live, Viewer
from augnet.console.live import BASELINE_STATES, as_dict
from augnet.console.schemas import BaselineOut, LineOut, NetworkOut

router = APIRouter(tags=["network"])


@router.get("/network", response_model=NetworkOut)
async def network(who: Viewer, live: Live) -> NetworkOut:
    stations = live.station_list()
    baselines = [BaselineOut(**as_dict(b)) for b in live.baseline_list()]
    by_state = {s: 0 for s in BASELINE_STATES}
    for b in baselines:
        by_state[b.state] += 1
    summary = live.network_summary()
    return NetworkOut(running=bool(summary or stations or baselines), summary=summary,
                      stations_total=len(stations), stations_up=sum(1 for s in stations if s.up and s.enabled),
                      baselines=baselines, baselines_by_state=by_state)


@router.get("/network/baselines", response_model=list[BaselineOut])
async def baselines(who: Viewer, live: Live) -> list[BaselineOut]:
    return [BaselineOut(**as_dict(b)) for b in live.baseline_list()]


@router.get("/line", response_model=LineOut)
async def line(who: Viewer, live: Live) -> LineOut:
    """The track centre line for the diagram: id, length [km], polyline [[lat, lon], ...]."""
    return LineOut(**{k: v for k, v in live.line_summary().items() if k in LineOut.model_fields})
