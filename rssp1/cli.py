"""`python -m rssp1 ...` (later also `augnet rssp1 ...`): capture inspection and SID recovery."""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

from rssp1.inspect import RSSP1_UDP_PORTS, format_report, inspect_captures, parse_device

app = typer.Typer(no_args_is_help=True, help="RSSP-I safety layer tools.")


@app.command()
def inspect(
    files: List[Path] = typer.Argument(..., help="pcapng (or pcap) captures", exists=True, dir_okay=False),
    device: Optional[List[str]] = typer.Option(
        None, "--device", help="ADDR:SID1,SID2[:SINIT1,SINIT2] of a sender whose check words to verify"
    ),
    port: Optional[List[int]] = typer.Option(None, "--port", help="UDP ports carrying RSSP-I (default 50000, 50001)"),
    all_udp: bool = typer.Option(False, "--all-udp", help="look for RSSP-I frames in every UDP datagram"),
    recover: bool = typer.Option(
        False, "--recover-sids", help="solve unknown senders' SIDs from two frames and verify the rest with them"
    ),
    cycle_ms: int = typer.Option(250, help="main cycle for the replay through a monitoring receiver, ms"),
    delta_time: int = typer.Option(3, help="deltaTime for the replay, cycles"),
    delay_time: int = typer.Option(3, help="DelayTime for the replay, cycles"),
) -> None:
    """Per source: frames seen, CRC16 passed, safety check words passed; per path, the receive verdicts."""
    from rssp1.config import LinkTiming

    try:
        devices = [parse_device(d) for d in device or []]
    except ValueError as exc:
        raise typer.BadParameter(str(exc), param_hint="--device") from exc
    try:
        report = inspect_captures(
            list(files), devices, ports=tuple(port) if port else RSSP1_UDP_PORTS, all_udp=all_udp, recover=recover,
            timing=LinkTiming(cycle_s=cycle_ms / 1000, delta_time=delta_time, delay_time=delay_time),
        )
    except ValueError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from exc
    typer.echo(format_report(report))


@app.command()
def demo(
    transport: str = typer.Option("udp", help="udp or tcp"),
    sealed: bool = typer.Option(False, help="wrap RSSP-I in the AES-GCM open-bearer envelope"),
    fault: str = typer.Option("section", help="section, corrections or link"),
    cycle_ms: int = typer.Option(250, help="main cycle, ms (field example: 250)"),
) -> None:
    """Stand-in centre -> RSSP-I over loopback -> RBC simulator: measure the time to alarm."""
    import asyncio

    from rssp1.config import LinkTiming
    from rssp1.loopback import time_to_alarm

    if transport not in ("udp", "tcp") or fault not in ("section", "corrections", "link"):
        raise typer.BadParameter("transport udp|tcp, fault section|corrections|link")
    timing = LinkTiming(cycle_s=cycle_ms / 1000)
    r = asyncio.run(time_to_alarm(timing, transport=transport, sealed=sealed, fault=fault))
    typer.echo(
        f"{r.transport}{' sealed' if r.sealed else ''}: link up after {r.link_up_s:.3f} s; fault '{fault}' -> "
        f"RBC alarm {r.alarm} after {r.time_to_alarm_s * 1000:.0f} ms ({r.centre_cycles} centre cycles)"
    )


def _simulator(kind: str, config: Path, listen: str, peer: str, duration: Optional[float]) -> None:
    import asyncio

    from rssp1.simulators import build_atp, build_rbc, load_link_file, parse_host_port, serve

    try:
        settings = load_link_file(config)
        node = build_rbc(settings) if kind == "rbc" else build_atp(settings)
        local, remote = parse_host_port(listen), parse_host_port(peer)
    except (ValueError, KeyError, TypeError) as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from exc
    typer.echo(f"{kind} simulator on {local[0]}:{local[1]}, peer {remote[0]}:{remote[1]}")
    try:
        link = asyncio.run(serve(node, node.endpoint.timing.cycle_s, local, remote, duration_s=duration, echo=typer.echo))
    except KeyboardInterrupt:
        return
    typer.echo(f"link {dict(link.stats)}; protocol {dict(node.endpoint.stats)}; application {dict(node.stats)}")


@app.command("rbc-sim")
def rbc_sim(
    config: Path = typer.Argument(..., exists=True, dir_okay=False, help="JSON link file (see rssp1/simulators.py)"),
    listen: str = typer.Option("0.0.0.0:50000", help="HOST:PORT to listen on"),
    peer: str = typer.Option(..., help="HOST:PORT of the control centre's link"),
    duration: Optional[float] = typer.Option(None, help="stop after this many seconds (default: run until ^C)"),
) -> None:
    """Run the RBC simulator on UDP; print each alarm as it is raised."""
    _simulator("rbc", config, listen, peer, duration)


@app.command("atp-sim")
def atp_sim(
    config: Path = typer.Argument(..., exists=True, dir_okay=False, help="JSON link file with a balise map"),
    listen: str = typer.Option("0.0.0.0:50001", help="HOST:PORT to listen on"),
    peer: str = typer.Option(..., help="HOST:PORT of the onboard unit's link"),
    duration: Optional[float] = typer.Option(None, help="stop after this many seconds (default: run until ^C)"),
) -> None:
    """Run the ATP simulator on UDP; print each alarm as it is raised."""
    _simulator("atp", config, listen, peer, duration)


@app.command()
def version() -> None:
    """Print the protocol constants this build uses."""
    from rssp1.checkword import SYS_CHK_WD
    from rssp1.crc import CRC16_CHECK, CRC32_CH1_CHECK, CRC32_CH2_CHECK

    typer.echo(
        f"RSSP-I: CRC16 check {CRC16_CHECK:#06x}, CRC32 checks {CRC32_CH1_CHECK:#010x}/{CRC32_CH2_CHECK:#010x}, "
        f"SYS_CHK_WD {SYS_CHK_WD[0]:#010x}/{SYS_CHK_WD[1]:#010x}"
    )


def main() -> None:
    app()
