"""Local NED <-> geodetic, exactly as PX4 does it (``lib/geo``'s ``MapProjection``).

Azimuthal equidistant projection on a sphere of radius :data:`EARTH_RADIUS_M` around a
reference point (PX4's EKF origin, GPS_GLOBAL_ORIGIN), so our local frame agrees with the
vehicle's. A local tangent-plane model: good to centimetres within a few kilometres of the
reference. Angles in degrees at the interface, north/east in metres.
"""
from __future__ import annotations

import math

EARTH_RADIUS_M = 6_371_000.0  # PX4's CONSTANTS_RADIUS_OF_EARTH [m]


def project(lat_deg: float, lon_deg: float, lat0_deg: float, lon0_deg: float) -> tuple[float, float]:
    """(north [m], east [m]) of a point relative to the reference (PX4 ``MapProjection::project``)."""
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    lat0, lon0 = math.radians(lat0_deg), math.radians(lon0_deg)
    sin0, cos0 = math.sin(lat0), math.cos(lat0)
    sin_lat, cos_lat = math.sin(lat), math.cos(lat)
    cos_dlon = math.cos(lon - lon0)
    c = math.acos(min(max(sin0 * sin_lat + cos0 * cos_lat * cos_dlon, -1.0), 1.0))
    k = c / math.sin(c) if abs(c) > 0.0 else 1.0
    north = k * (cos0 * sin_lat - sin0 * cos_lat * cos_dlon) * EARTH_RADIUS_M
    east = k * cos_lat * math.sin(lon - lon0) * EARTH_RADIUS_M
    return north, east


def reproject(north_m: float, east_m: float, lat0_deg: float, lon0_deg: float) -> tuple[float, float]:
    """(lat [deg], lon [deg]) of a local point [m]: the inverse of :func:`project` (PX4
    ``MapProjection::reproject``)."""
    lat0, lon0 = math.radians(lat0_deg), math.radians(lon0_deg)
    sin0, cos0 = math.sin(lat0), math.cos(lat0)
    x, y = north_m / EARTH_RADIUS_M, east_m / EARTH_RADIUS_M
    c = math.hypot(x, y)
    if c > 0.0:
        sin_c, cos_c = math.sin(c), math.cos(c)
        lat = math.asin(cos_c * sin0 + x * sin_c * cos0 / c)
        lon = lon0 + math.atan2(y * sin_c, c * cos0 * cos_c - x * sin0 * sin_c)
    else:
        lat, lon = lat0, lon0
    return math.degrees(lat), math.degrees(lon)


def wrap_pi(angle_rad: float) -> float:
    """Angle wrapped to (-pi, pi] [rad]."""
    a = math.remainder(angle_rad, 2 * math.pi)
    return math.pi if a == -math.pi else a
