"""RTCM 3 codec: message layouts as data, encoders and decoders; framing and CRC-24Q are augwire's
(`augwire.rtcm_framing`, `augwire.crc24q`), re-exported here as part of the codec's one entry point.

Which function to call:

(a) split a byte stream into frames (sans-IO, never raises on input)::

        reader = RtcmStreamReader()
        for fr in reader.feed(chunk): ...        # Frame(msg_type, payload, raw); reader.stats counts
        read_frames(path)                        # a whole file, with stats and any truncated tail
        MessageReader().feed(chunk)              # frames and decode in one step; bad payloads counted

(b) decode any frame or payload::

        msg = decode(frame_or_payload)           # RtcmMessage (.fields like pyrtcm), MsmMessage
                                                 # (numpy arrays) or UnknownMessage (payload kept)

(c) encode a message::

        payload = encode(msg); raw = encode_frame(msg)      # or frame(payload)
        RtcmMessage(1005, {"DF003": 7, "DF025": x, ...})    # pyrtcm's field names and scaled values
        RtcmMessage(1077, msm.to_fields())                  # MSM too (or an MsmMessage of raw arrays)

(d) MSM <-> observables (pseudorange m, phase cycles, Doppler Hz, CNR dB-Hz, lock ms; NaN = absent)::

        obs = msm_to_observables(msm)
        msm = observables_to_msm(obs, level=7, station_id=..., epoch=tow_ms)
        msgs = observables_to_msm_list(...)      # splits > 64 cells over several MSM (DF393)
        phase_offset_cycles(pr, cp, lam)         # phases must lie within 1171 m of the pseudorange:
                                                 # subtract this (kept for the lock) or they go invalid

(e) batch encode one MSM type for many receivers (VRS per train), arrays (nrx, nsat, nsig)::

        batch = encode_msm_batch("G", 7, sat_ids, sig_ids, station_ids, epochs, pr, cp, dop, cnr, lock)
        batch[i]                                 # framed bytes of receiver i; batch.data is all of them
        encode_fixed_batch(1006, {"DF003": ids, "DF025": x, ...})   # e.g. every train's VRS position

Supported: 1005, 1006, 1033, 1019, 1042, 1045, 1046 and MSM4-7 of GPS, GLONASS, Galileo, SBAS,
QZSS, BeiDou, NavIC (observables need the system in ``augnet.gnss.signals``: G, E, C). Values are
those pyrtcm reports (scaled, DF names); MSM epochs are the raw 30-bit field (TOW ms in the system's
own time scale: BDT for BeiDou; day-of-week << 27 | tk for GLONASS).
"""

from augnet.gnss.rtcm.batch import EncodedBatch, encode_fixed_batch, encode_msm_batch
from augnet.gnss.rtcm.codec import (
    Message,
    MessageReader,
    RtcmMessage,
    UnknownMessage,
    decode,
    encode,
    encode_frame,
    text_fields,
)
from augnet.gnss.rtcm.errors import DecodeError, EncodeError
from augnet.gnss.rtcm.layouts import SUPPORTED_TYPES
from augnet.gnss.rtcm.msm import MsmMessage, decode_msm, encode_msm, make_msm, msm_from_fields
from augnet.gnss.rtcm.observables import (
    Observables,
    lock_indicator_df402,
    lock_indicator_df407,
    lock_time_df402,
    lock_time_df407,
    msm_to_observables,
    observables_to_msm,
    observables_to_msm_list,
    phase_offset_cycles,
)
from augwire.crc24q import crc24q
from augwire.rtcm_framing import Frame, RtcmStreamReader, StreamStats, frame, iter_frames, read_frames

__all__ = [
    "DecodeError", "EncodeError", "EncodedBatch", "Frame", "Message", "MessageReader", "MsmMessage", "Observables",
    "RtcmMessage", "RtcmStreamReader", "SUPPORTED_TYPES", "StreamStats", "UnknownMessage", "crc24q",
    "decode", "decode_msm", "encode", "encode_frame", "encode_fixed_batch", "encode_msm", "encode_msm_batch", "frame",
    "iter_frames", "lock_indicator_df402", "lock_indicator_df407", "lock_time_df402", "lock_time_df407",
    "make_msm", "msm_from_fields", "msm_to_observables", "observables_to_msm", "observables_to_msm_list",
    "phase_offset_cycles", "read_frames", "text_fields",
]
