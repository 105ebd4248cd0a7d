"""Wire primitives benchmark (augwire): CRC-24Q against pyrtcm's and against our own byte loop by
length (where CRC24Q_NUMPY_MIN_BYTES comes from), the RTCM framer and the caster's aligner on a
stream of frames, and the chunked decoder per chunk, whole or split across reads.

Each figure is CPU time of this process (time.process_time), best of several repeats.
Run: ``augnet bench wire`` or ``python -m augnet.bench.wire [--json]``.
"""

from __future__ import annotations

import json
import sys

import numpy as np

from augnet.bench.rtcm import REPEATS, _rate

CRC_LENGTHS = (16, 32, 48, 64, 128, 325, 1026)
STREAM_FRAMES = 800  # ~0.4 MB of frames, payloads 20-1023 bytes
READ_BYTES = 1400  # one TCP segment's worth per read


def _stream(seed: int = 2026) -> list[bytes]:
    from augwire.rtcm_framing import frame

    rng = np.random.default_rng(seed)
    sizes = rng.integers(20, 1024, STREAM_FRAMES)
    return [frame(b"\x3e\xd0" + rng.integers(0, 256, int(n) - 2, dtype=np.uint8).tobytes()) for n in sizes]


def _pieces(data: bytes, size: int = READ_BYTES) -> list[bytes]:
    return [data[i : i + size] for i in range(0, len(data), size)]


def measure() -> dict:
    from pyrtcm.rtcmhelpers import calc_crc24q

    from augwire.chunked import ChunkedDecoder, encode_chunk
    from augwire.crc24q import crc24q, crc24q_bytewise
    from augwire.rtcm_framing import RtcmFrameAligner, RtcmStreamReader

    rng = np.random.default_rng(24)
    crc: dict[str, dict[str, float]] = {}
    for n in CRC_LENGTHS:
        data = rng.integers(0, 256, n, dtype=np.uint8).tobytes()
        crc[f"{n} B"] = {"crc24q": _rate(lambda: crc24q(data)), "byte loop": _rate(lambda: crc24q_bytewise(data)),
                         "pyrtcm": _rate(lambda: calc_crc24q(data))}
    frames = _stream()
    stream = b"".join(frames)
    reads = _pieces(stream)
    chunks = [encode_chunk(f) for f in frames]
    chunk_reads = _pieces(b"".join(chunks))

    def read_frames() -> None:
        reader = RtcmStreamReader()
        for piece in reads:
            reader.feed(piece)

    def align() -> None:
        aligner = RtcmFrameAligner()
        for piece in reads:
            aligner.feed(piece)

    def dechunk(pieces: list[bytes]):
        def run() -> None:
            decoder = ChunkedDecoder(max_chunk_bytes=None)
            for piece in pieces:
                decoder.feed(piece)
        return run

    stream_rates = {
        "RtcmStreamReader": _rate(read_frames, per_call=len(frames)),
        "RtcmFrameAligner": _rate(align, per_call=len(frames)),
        "ChunkedDecoder, a chunk per read": _rate(dechunk(chunks), per_call=len(frames)),
        f"ChunkedDecoder, {READ_BYTES} B reads": _rate(dechunk(chunk_reads), per_call=len(frames)),
    }
    return {"crc_calls_per_s": crc, "frames_per_s": stream_rates,
            "stream": f"{len(frames)} frames, {len(stream)} bytes, read {READ_BYTES} B at a time"}


def print_table(result: dict, out=None) -> None:
    out = sys.stdout if out is None else out
    print(f"augwire benchmark (CPU time, best of {REPEATS} repeats)", file=out)
    print(f"{'CRC-24Q of':<12}{'crc24q/s':>12}{'byte loop/s':>14}{'pyrtcm/s':>12}{'vs pyrtcm':>11}", file=out)
    for case, v in result["crc_calls_per_s"].items():
        print(f"{case:<12}{v['crc24q']:>12,.0f}{v['byte loop']:>14,.0f}{v['pyrtcm']:>12,.0f}"
              f"{v['crc24q'] / v['pyrtcm']:>10.1f}x", file=out)
    print(f"\n{result['stream']}", file=out)
    print(f"{'case':<36}{'frames/s':>12}", file=out)
    for case, rate in result["frames_per_s"].items():
        print(f"{case:<36}{rate:>12,.0f}", file=out)


def main(argv: list[str] | None = None) -> None:
    """Print the table (or, with --json, the figures as JSON)."""
    result = measure()
    if "--json" in (sys.argv[1:] if argv is None else argv):
        print(json.dumps(result, indent=2))
    else:
        print_table(result)


if __name__ == "__main__":
    main()
