"""Privacy zones and coarsening, shared by the logger (before anything is written) and
``analyze redact`` (on logs written without them).

A zone is a circle (``lat``, ``lon`` [deg], ``radius_m``) or a polygon (``polygon = [[lat, lon],
…]``, at least three corners) on the WGS-84 sphere of mean radius; inside a zone no position, no
NMEA and no GPS time is kept. Coarsening snaps positions to a grid of ``position_grid_m`` and
keeps wall-clock time only to ``time_resolution_s``: the offset between the monotonic clock and
wall-clock (or GPS) time is rounded down to the resolution, so durations stay exact while no
record tells the time of day better than the resolution.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

EARTH_RADIUS_M = 6_371_008.8
"""Mean earth radius (IUGG) [m]; distances inside a zone of a few km are good to ~0.3 %."""
METRES_PER_DEGREE = EARTH_RADIUS_M * math.pi / 180.0


VEHICLE_POSITION_PGN = 65267
"""J1939-71 Vehicle Position: SPN 584 latitude, SPN 585 longitude (1e-7 deg/bit, offset -210 deg)."""
TIME_DATE_PGN = 65254
"""J1939-71 Time/Date: the wall-clock time of day and date."""
POSITION_PGNS = (VEHICLE_POSITION_PGN, TIME_DATE_PGN)


def frame_pgns(arbitration_id, extended):
    """J1939 PGN of PDU2 frames (29-bit identifiers); -1 for standard frames. Arrays in, array out."""
    import numpy as np

    arbitration_id = np.asarray(arbitration_id, dtype=np.int64)
    return np.where(np.asarray(extended, dtype=bool), (arbitration_id >> 8) & 0x3FFFF, -1)


def vehicle_positions(data):
    """(latitude, longitude) [deg] of Vehicle Position frames (``data``: n × 8 bytes); NaN where
    the receiver sent "not available" (above 0xFAFFFFFF)."""
    import numpy as np

    raw = np.ascontiguousarray(data, dtype=np.uint8).reshape(-1, 8).view("<u4").astype(np.float64)
    raw[raw > 0xFAFFFFFF] = np.nan
    return raw[:, 0] * 1e-7 - 210.0, raw[:, 1] * 1e-7 - 210.0


@dataclass(frozen=True)
class Zone:
    name: str
    lat: float = 0.0
    lon: float = 0.0
    radius_m: float = 0.0
    polygon: tuple[tuple[float, float], ...] = ()

    def contains(self, lat: float, lon: float) -> bool:
        if self.polygon:
            return _in_polygon(self.polygon, lat, lon)
        return distance_m(self.lat, self.lon, lat, lon) <= self.radius_m


def distance_m(lat1: float, lon1: float, lat2: float, lon2: float) -> float:
    """Great-circle distance (haversine) [m]."""
    p1, p2 = math.radians(lat1), math.radians(lat2)
    a = math.sin((p2 - p1) / 2) ** 2 + math.cos(p1) * math.cos(p2) * math.sin(math.radians(lon2 - lon1) / 2) ** 2
    return 2 * EARTH_RADIUS_M * math.asin(min(1.0, math.sqrt(a)))


def _in_polygon(corners, lat: float, lon: float) -> bool:
    """Even-odd rule in a local equirectangular plane around the point (zones are small)."""
    scale = math.cos(math.radians(lat))
    inside = False
    n = len(corners)
    for i in range(n):
        y1, x1 = corners[i]
        y2, x2 = corners[(i + 1) % n]
        x1 = ((x1 - lon + 180.0) % 360.0 - 180.0) * scale
        x2 = ((x2 - lon + 180.0) % 360.0 - 180.0) * scale
        y1, y2 = y1 - lat, y2 - lat
        if (y1 > 0) != (y2 > 0) and 0 < x1 + (x2 - x1) * (0 - y1) / (y2 - y1):
            inside = not inside
    return inside


def zones_from_tables(tables: list[dict], where: str = "zones") -> list[Zone]:
    """Zones from TOML tables (``[[privacy.zones]]`` of the logger configuration or ``[[zones]]``
    of a zones file); raises ``ValueError`` with a one-line message naming the bad entry."""
    zones = []
    known = {"name", "lat", "lon", "radius_m", "polygon"}
    for index, table in enumerate(tables):
        key = f"{where}[{index}]"
        if not isinstance(table, dict):
            raise ValueError(f"{key} must be a table with lat, lon, radius_m or a polygon")
        unknown = set(table) - known
        if unknown:
            raise ValueError(f"{key}: unknown key {sorted(unknown)[0]}; known: {', '.join(sorted(known))}")
        name = str(table.get("name", f"zone {index}"))
        if "polygon" in table:
            if {"lat", "lon", "radius_m"} & set(table):
                raise ValueError(f"{key}: a zone is a circle (lat, lon, radius_m) or a polygon, not both")
            corners = table["polygon"]
            if (not isinstance(corners, list) or len(corners) < 3
                    or not all(isinstance(c, list) and len(c) == 2 and all(_is_number(v) for v in c) for c in corners)):
                raise ValueError(f"{key}.polygon must be a list of at least 3 [lat, lon] pairs")
            polygon = tuple((float(a), float(b)) for a, b in corners)
            for lat, lon in polygon:
                _check_lat_lon(key, lat, lon)
            _check_simple_polygon(key, polygon)
            zones.append(Zone(name, polygon=polygon))
            continue
        missing = [k for k in ("lat", "lon", "radius_m") if k not in table]
        if missing:
            raise ValueError(f"{key}: a circle needs lat, lon and radius_m (missing {', '.join(missing)})")
        if not all(_is_number(table[k]) for k in ("lat", "lon", "radius_m")):
            raise ValueError(f"{key}: lat, lon and radius_m must be numbers")
        lat, lon, radius = float(table["lat"]), float(table["lon"]), float(table["radius_m"])
        _check_lat_lon(key, lat, lon)
        if not radius > 0:
            raise ValueError(f"{key}.radius_m must be > 0, got {radius!r}")
        zones.append(Zone(name, lat, lon, radius))
    return zones


def _local_m(polygon) -> list[tuple[float, float]]:
    """Corners in metres east and north of the first (equirectangular: zones are a few km)."""
    lat0, lon0 = polygon[0]
    scale = math.cos(math.radians(lat0))
    return [((lon - lon0) * METRES_PER_DEGREE * scale, (lat - lat0) * METRES_PER_DEGREE) for lat, lon in polygon]


def _crosses(a, b, c, d) -> bool:
    """Segments ab and cd cross or touch (orientation test)."""
    def side(p, q, r):
        value = (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])
        return (value > 1e-9) - (value < -1e-9)

    def on(p, q, r):
        return min(p[0], q[0]) - 1e-9 <= r[0] <= max(p[0], q[0]) + 1e-9 and \
            min(p[1], q[1]) - 1e-9 <= r[1] <= max(p[1], q[1]) + 1e-9

    s1, s2, s3, s4 = side(a, b, c), side(a, b, d), side(c, d, a), side(c, d, b)
    if s1 != s2 and s3 != s4:
        return True
    return any(s == 0 and on(p, q, r) for s, p, q, r in ((s1, a, b, c), (s2, a, b, d), (s3, c, d, a), (s4, c, d, b)))


def _check_simple_polygon(key: str, polygon) -> None:
    """A zone's polygon must enclose an area (1 m² at least) without crossing itself: the
    even-odd test of a self-crossing one leaves holes where the zone was meant to be."""
    points = _local_m(polygon)
    if points[0] == points[-1] and len(points) > 3:
        points = points[:-1]  # a closed ring's repeated first corner
    edges = list(zip(points, points[1:] + points[:1]))
    for i, (a, b) in enumerate(edges):
        for j in range(i + 2, len(edges)):
            if i == 0 and j == len(edges) - 1:
                continue  # the first and last edge share a corner
            if _crosses(a, b, *edges[j]):
                raise ValueError(f"{key}.polygon crosses itself (edges {i + 1} and {j + 1}); "
                                 "give its corners in order around the zone")
    area = 0.5 * abs(sum(x1 * y2 - x2 * y1 for (x1, y1), (x2, y2) in zip(points, points[1:] + points[:1])))
    if area < 1.0:
        raise ValueError(f"{key}.polygon encloses no area ({area:.2g} m²): its corners lie on a line or repeat")


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _check_lat_lon(key: str, lat: float, lon: float) -> None:
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
        raise ValueError(f"{key}: ({lat}, {lon}) is not a latitude/longitude in degrees")


def in_any(zones: list[Zone], lat: float, lon: float) -> bool:
    return any(zone.contains(lat, lon) for zone in zones)


def snap_position(lat: float, lon: float, grid_m: float) -> tuple[float, float]:
    """The centre of the ``grid_m`` × ``grid_m`` cell holding (lat, lon) [deg]: rows of constant
    latitude step, each row's longitude step sized for its own latitude."""
    dlat = grid_m / METRES_PER_DEGREE
    row = math.floor(lat / dlat)
    lat_c = (row + 0.5) * dlat
    dlon = grid_m / (METRES_PER_DEGREE * max(math.cos(math.radians(lat_c)), 1e-6))
    lon_c = (math.floor(lon / dlon) + 0.5) * dlon
    return lat_c, ((lon_c + 180.0) % 360.0) - 180.0


class CoarseClock:
    """Wall-clock (or GPS) times to ``resolution_ns``, as ``t_mono_ns + rounded offset``.

    Rounding each time down on its own would let a reader recover the exact offset from many
    (exact monotonic, rounded wall) pairs; rounding the *offset* gives every record the same one.
    The rounded offset is kept while the true one stays within ``hysteresis_ns`` of its window,
    so arrival jitter at a window edge never flips it back and forth; a clock step moves it.
    """

    def __init__(self, resolution_ns: int, hysteresis_ns: int = 2_000_000_000):
        self.resolution_ns = int(resolution_ns)
        self.hysteresis_ns = min(int(hysteresis_ns), self.resolution_ns // 4)
        self._offset_ns: int | None = None

    def __call__(self, t_wall_ns: int | None, t_mono_ns: int) -> int | None:
        if t_wall_ns is None or self.resolution_ns <= 0:
            return t_wall_ns
        offset = int(t_wall_ns) - int(t_mono_ns)
        kept = self._offset_ns
        if kept is None or not kept - self.hysteresis_ns <= offset < kept + self.resolution_ns + self.hysteresis_ns:
            kept = self._offset_ns = offset // self.resolution_ns * self.resolution_ns
        return int(t_mono_ns) + kept
