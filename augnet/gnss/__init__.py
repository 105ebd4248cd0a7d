"""GNSS core: pure functions and small value types (time, signals, ephemeris, geometry, RINEX, RTCM 3).

No sockets, no threads, no global state. Arrays run over satellites and epochs.
"""
