"""RSSP-I railway signal safety protocol, and the centre -> RBC and onboard -> ATP links on top of it.

Standard library only (the open-bearer envelope uses `cryptography`; the CRCs and rssp1.batch run as
compiled kernels when numba imports, the pure-Python reference kept and tested against them). A
sans-IO core -- CRCs, timestamp LFSRs, check words, frames, the per-link `Endpoint` state machine,
application messages -- and thin asyncio UDP/TCP transports. See README.md in this folder for the
module map, the receive rules per threat, the API the control centre and the onboard core call, and
key provisioning.
"""

from rssp1.config import DeviceConfig, LinkConfig, LinkTiming, link_config_from_mapping
from rssp1.endpoint import DataReceived, Endpoint, FrameDropped, LinkDown, LinkState, LinkUp

__all__ = [
    "DataReceived",
    "DeviceConfig",
    "Endpoint",
    "FrameDropped",
    "LinkConfig",
    "LinkDown",
    "LinkState",
    "LinkTiming",
    "LinkUp",
    "link_config_from_mapping",
]
