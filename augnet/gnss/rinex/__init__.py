"""RINEX 3 navigation and observation files (read and write), RINEX 2.11 observations (read).

Readers return array-friendly values: per epoch GPST times, satellite ids, one (epochs x
satellites) array per observation type with NaN where missing.  Any malformed file raises
`RinexError`, which names the file and the line number.
"""

from augnet.gnss.rinex.errors import RinexError
from augnet.gnss.rinex.nav import NavFile, NavHeader, read_nav, write_nav
from augnet.gnss.rinex.obs import ObsData, ObsHeader, read_obs, write_obs

__all__ = [
    "RinexError",
    "NavFile",
    "NavHeader",
    "read_nav",
    "write_nav",
    "ObsData",
    "ObsHeader",
    "read_obs",
    "write_obs",
]
