"""GPS fixes to local metres: east x, north y around a reference fix.

Equirectangular (local tangent plane) approximation on the WGS84 ellipsoid:
y = M(lat0) * dlat, x = N(lat0) * cos(lat0) * dlon, with M and N the meridional and
prime-vertical radii of curvature at the reference latitude (angles in radians).
Accuracy: the error is second order in the distance d from the reference, about
d * tan(lat0) * (north offset / 6371 km) from the change of cos(lat) over the area:
under 1 mm within 100 m and about 0.2 m at 1 km at 49 degrees latitude -- far below
what a GPS fix is worth (2-5 m). Do not use it for areas beyond ~10 km or near a pole.
"""

from __future__ import annotations

import numpy as np

WGS84_A = 6378137.0                 # semi-major axis, metres
WGS84_E2 = 6.69437999014e-3         # first eccentricity squared


def local_metres(lat: np.ndarray, lon: np.ndarray, lat0: float, lon0: float) -> tuple[np.ndarray, np.ndarray]:
    """(x east, y north) in metres of the fixes (degrees) relative to (lat0, lon0)."""
    phi0 = np.radians(lat0)
    w = np.sqrt(1.0 - WGS84_E2 * np.sin(phi0) ** 2)
    meridional = WGS84_A * (1.0 - WGS84_E2) / w ** 3
    prime_vertical = WGS84_A / w
    dlon = (np.asarray(lon, dtype=np.float64) - lon0 + 180.0) % 360.0 - 180.0  # across the date line
    x = prime_vertical * np.cos(phi0) * np.radians(dlon)
    y = meridional * np.radians(np.asarray(lat, dtype=np.float64) - lat0)
    return x, y


def heading_to_yaw(direction_deg: np.ndarray) -> np.ndarray:
    """Compass heading (degrees clockwise from north) to yaw (radians counter-clockwise
    from east, the x axis), wrapped to [-pi, pi): the convention of ``engine.poses``."""
    yaw = np.radians(90.0 - np.asarray(direction_deg, dtype=np.float64))
    return (yaw + np.pi) % (2 * np.pi) - np.pi
