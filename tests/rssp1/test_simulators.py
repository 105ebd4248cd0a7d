"""The RBC and ATP simulators as UDP services built from JSON link files."""

from __future__ import annotations

import asyncio
import json
import socket

import pytest
from typer.testing import CliRunner

from rssp1.atp import BaliseLocation, OnboardAtpLink
from rssp1.cli import app
from rssp1.endpoint import Endpoint
from rssp1.loopback import DEMO_CENTRE, DEMO_RBC, StandInCentre
from rssp1.messages import AlarmCode, SectionStatus
from rssp1.rbc import CentreRbcLink
from rssp1.simulators import build_atp, build_rbc, parse_host_port, serve
from rssp1.transport import UdpLink

from .test_rbc_atp import ATP, ONBOARD

CYCLE_S = 0.05
TIMING = {"cycle_s": CYCLE_S, "delta_time": 3, "life_time": 4, "delay_time": 3}


def device(cfg):
    return {"address": hex(cfg.address), "sid": [hex(v) for v in cfg.sid], "dataver": list(cfg.dataver)}


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.timeout(60)
@pytest.mark.parametrize("sealed", [False, True], ids=["plain", "sealed"])
def test_rbc_service_reports_a_section_alarm(sealed):
    key = "11" * 32
    settings = {"local": device(DEMO_RBC), "peer": device(DEMO_CENTRE), "timing": TIMING, "max_correction_age_s": 2.0}
    if sealed:
        settings["keys"] = {"3": key}
    rbc = build_rbc(settings)
    lines: list[str] = []

    async def scenario():
        rbc_port = free_udp_port()
        centre_ep = Endpoint(DEMO_CENTRE, DEMO_RBC, rbc.endpoint.timing)
        if sealed:
            from rssp1.envelope import Keyring, SealedEndpoint

            centre_ep = SealedEndpoint(centre_ep, Keyring.from_mapping({"3": key}))
        centre = StandInCentre(CentreRbcLink(centre_ep))
        centre_link = await UdpLink.open(centre, CYCLE_S, ("127.0.0.1", 0), ("127.0.0.1", rbc_port))
        service = asyncio.create_task(
            serve(rbc, CYCLE_S, ("127.0.0.1", rbc_port), centre_link.local_address, duration_s=2.0, echo=lines.append)
        )
        runner = asyncio.create_task(centre_link.run())
        for _ in range(200):
            await asyncio.sleep(0.01)
            if rbc.effective_status(7) is SectionStatus.OK:
                break
        centre.link.set_section(7, SectionStatus.DO_NOT_USE)
        await service
        centre_link.close()
        runner.cancel()
        await asyncio.gather(runner, return_exceptions=True)

    asyncio.run(scenario())
    assert rbc.first_alarm(AlarmCode.SECTION_DO_NOT_USE, 7) is not None
    assert any("ALARM SECTION_DO_NOT_USE section 7" in line for line in lines), lines


@pytest.mark.timeout(60)
def test_atp_service_takes_passages():
    settings = {"local": device(ATP), "peer": device(ONBOARD), "timing": TIMING,
                "balises": {"70001": [3, 1_000_000], "0x11172": [3, 1_500_000]}}
    atp = build_atp(settings)
    assert atp.balise_map[70002] == BaliseLocation(3, 1_500_000)  # hex keys accepted

    async def scenario():
        atp_port = free_udp_port()
        onboard = OnboardAtpLink(Endpoint(ONBOARD, ATP, atp.endpoint.timing), train_id=7)
        link = await UdpLink.open(onboard, CYCLE_S, ("127.0.0.1", 0), ("127.0.0.1", atp_port))
        service = asyncio.create_task(serve(atp, CYCLE_S, ("127.0.0.1", atp_port), link.local_address, duration_s=1.5,
                                            echo=lambda line: None))
        runner = asyncio.create_task(link.run())
        onboard.report_balise(time_ms=1, balise_group=70001, location=BaliseLocation(3, 1_000_000), reverse=False,
                              confidence_mm=500, speed_mm_s=30_000)
        await service
        link.close()
        runner.cancel()
        await asyncio.gather(runner, return_exceptions=True)
        return onboard

    onboard = asyncio.run(scenario())
    assert [t.balise_group for t in atp.passages] == [70001] and onboard.pending == []


def test_cli_rejects_bad_files_and_addresses(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    out = CliRunner().invoke(app, ["rbc-sim", str(bad), "--peer", "127.0.0.1:9"])
    assert out.exit_code == 2 and "error" in out.output
    good = tmp_path / "good.json"
    good.write_text(json.dumps({"local": device(DEMO_RBC), "peer": device(DEMO_CENTRE), "timing": TIMING}))
    out = CliRunner().invoke(app, ["rbc-sim", str(good), "--peer", "nowhere"])
    assert out.exit_code == 2
    out = CliRunner().invoke(app, ["rbc-sim", str(good), "--listen", "127.0.0.1:0", "--peer", "127.0.0.1:9",
                                   "--duration", "0.2"])
    assert out.exit_code == 0 and "rbc simulator on 127.0.0.1:0" in out.output
    assert parse_host_port(":5") == ("0.0.0.0", 5)
