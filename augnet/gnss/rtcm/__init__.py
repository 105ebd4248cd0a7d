"""RTCM 3 codec: framing (CRC-24Q), message layouts as data, encoders and decoders."""
