"""Physical and system constants, each named once with its unit and source."""

import math

SPEED_OF_LIGHT_M_S = 299_792_458.0  # exact, SI definition; IS-GPS-200 20.3.4.3

# Earth rotation rate and gravitational constants differ slightly per system's ICD.
OMEGA_E_GPS_RAD_S = 7.2921151467e-5  # IS-GPS-200 Table 20-IV (WGS 84)
OMEGA_E_GAL_RAD_S = 7.2921151467e-5  # Galileo OS SIS ICD 5.1.1
OMEGA_E_BDS_RAD_S = 7.2921150e-5  # BDS-SIS-ICD-B1I 5.2.4.10 (CGCS2000)
GM_GPS_M3_S2 = 3.986005e14  # IS-GPS-200 Table 20-IV
GM_GAL_M3_S2 = 3.986004418e14  # Galileo OS SIS ICD 5.1.1
GM_BDS_M3_S2 = 3.986004418e14  # BDS-SIS-ICD-B1I 5.2.4.10

# Relativistic clock correction constant F = -2 sqrt(GM) / c^2 [s / m^0.5]
REL_F_GPS_S_SQRTM = -4.442807633e-10  # IS-GPS-200 20.3.3.3.3.1
REL_F_GAL_S_SQRTM = -2.0 * math.sqrt(GM_GAL_M3_S2) / SPEED_OF_LIGHT_M_S**2
REL_F_BDS_S_SQRTM = -2.0 * math.sqrt(GM_BDS_M3_S2) / SPEED_OF_LIGHT_M_S**2

# WGS 84 ellipsoid (NIMA TR8350.2); CGCS2000 and GTRF differ by < 0.1 mm in b, ignored.
WGS84_A_M = 6_378_137.0
WGS84_F = 1.0 / 298.257223563
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)

SECONDS_PER_WEEK = 604_800.0
SECONDS_PER_DAY = 86_400.0

# BeiDou time is GPS time minus 14 s (BDS-SIS-ICD 4.2); Galileo System Time is aligned with GPST
# (GST-GPST offset is broadcast and of the order of ns; ignored here).
BDT_MINUS_GPST_S = -14.0
# BDS week 0 begins 2006-01-01 00:00:00 BDT, which is GPS week 1356 + 14 s.
BDS_WEEK_OFFSET_FROM_GPS = 1356
# Galileo week 0 begins at GPS week 1024 (1999-08-22).
GAL_WEEK_OFFSET_FROM_GPS = 1024

# BDS GEO satellites: PRN 1-5 and 59-63 (BDS-SIS-ICD-B1I 3.0, Table 5-x; RTKLIB uses the same split).
BDS_GEO_PRNS = frozenset({1, 2, 3, 4, 5, 59, 60, 61, 62, 63})
