"""NMEA 0183 sentences of a GPS receiver → ``/gps/fix`` records, one per receiver epoch.

RMC, GGA, GSA, GST and VTG of one epoch (same UTC time of day) are merged into one
``foxglove.LocationFix``-compatible fix, with the horizontal and vertical accuracy from GST. A
receiver that sends no GST (a u-blox 7 unless asked) still states its geometry: GGA's HDOP and
GSA's VDOP go into the fix, from which the analysis takes an accuracy (`analysis.gnss_accuracy`). Bad
checksums, proprietary sentences and sentences pynmea2 cannot parse are counted and skipped. The
logger's GPS source parses its serial port with this, and the analysis a receiver's log file, so
both give the same fixes from the same bytes.
"""

from __future__ import annotations

import datetime as dt
import functools
import math
import operator

import pynmea2

from . import location_fix

KNOT_MPS = 1852.0 / 3600.0
FIX_TYPES = {"RMC", "GGA", "GSA", "GST", "VTG", "GLL", "GNS"}
"""Sentences of an epoch; GLL and GNS add nothing to the fix but belong to their epoch by their
time, so the logger's privacy judges their positions with it."""
FALLBACK_TYPES = {"VTG", "GSA"}
"""Sentences only needed when RMC (speed), GGA (HDOP) or GST (the accuracy, for which GSA's VDOP
stands in) left a field empty: parsed only then."""


def nmea_checksum_ok(sentence: str) -> bool:
    """True if ``$...*hh`` carries the XOR checksum of the characters between ``$`` and ``*``."""
    star = sentence.rfind("*")
    if not sentence.startswith(("$", "!")) or star < 0 or len(sentence) < star + 3:
        return False
    try:
        expected = int(sentence[star + 1:star + 3], 16)
    except ValueError:
        return False
    return functools.reduce(operator.xor, sentence[1:star].encode("ascii", "replace"), 0) == expected


@functools.lru_cache(maxsize=4)
def _date(ddmmyy: str) -> dt.date | None:
    """RMC's date field (one parse per day, not per sentence)."""
    try:
        return pynmea2.nmea_utils.datestamp(ddmmyy) if ddmmyy else None
    except ValueError:
        return None


def _float(value) -> float | None:
    try:
        return float(value) if value not in (None, "") else None
    except (TypeError, ValueError):
        return None


class Epoch:
    """What the sentences of one receiver epoch said."""

    def __init__(self, time_key: str, t_mono_ns: int):
        self.time_key = time_key
        self.t_mono_ns = t_mono_ns
        self.fields: dict = {}
        self.fallbacks: list[str] = []

    def add(self, msg) -> None:
        kind = msg.sentence_type
        f = self.fields
        if kind == "GGA":
            f["fix_quality"] = int(msg.gps_qual or 0)
            if msg.lat and msg.lon:
                f["latitude"], f["longitude"] = msg.latitude, msg.longitude
            f["altitude"] = _float(msg.altitude)
            f["satellites"] = int(msg.num_sats or 0)
            f["hdop"] = _float(msg.horizontal_dil)
        elif kind == "RMC":
            speed_knots = _float(msg.spd_over_grnd)
            if speed_knots is not None:
                f["speed_mps"] = speed_knots * KNOT_MPS
            f["course_deg"] = _float(msg.true_course)
            date_index = msg.name_to_idx["datestamp"]  # the raw field: pynmea2's property parses it anew
            date = _date(msg.data[date_index] if len(msg.data) > date_index else "")
            time_of_day = msg.timestamp
            if date and time_of_day:
                f["utc"] = dt.datetime.combine(date, time_of_day)
        elif kind == "VTG":
            speed_kmh = _float(msg.spd_over_grnd_kmph)
            if "speed_mps" not in f and speed_kmh is not None:
                f["speed_mps"] = speed_kmh / 3.6
        elif kind == "GST":
            lat_err, lon_err, alt_err = (_float(msg.std_dev_latitude), _float(msg.std_dev_longitude),
                                         _float(msg.std_dev_altitude))
            if lat_err is not None and lon_err is not None:
                f["h_acc_m"] = math.hypot(lat_err, lon_err)
                f["east_north_sigma_m"] = (lon_err, lat_err)
            f["v_acc_m"] = alt_err
        elif kind == "GSA":
            f["hdop"] = f.get("hdop") or _float(msg.hdop)
            f["vdop"] = _float(msg.vdop)

    def add_fallbacks(self) -> int:
        """Parse the VTG/GSA kept aside if RMC, GGA or GST left their field empty; returns parse errors."""
        f, errors = self.fields, 0
        for text in self.fallbacks:
            if (text[3:6] == "VTG" and "speed_mps" not in f) or (
                    text[3:6] == "GSA" and (not f.get("hdop") or f.get("v_acc_m") is None)):
                try:
                    self.add(pynmea2.parse(text))
                except (pynmea2.ParseError, ValueError, TypeError, AttributeError):
                    errors += 1
        return errors

    def fix(self, wall_time_ns: int) -> dict | None:
        f = self.fields
        if not f.get("fix_quality") or "latitude" not in f or f.get("altitude") is None:
            return None
        gps_ns = None
        if "utc" in f:
            gps_ns = int(f["utc"].replace(tzinfo=dt.timezone.utc).timestamp()) * 1_000_000_000 + \
                f["utc"].microsecond * 1000
        return location_fix(
            self.t_mono_ns, gps_ns if gps_ns is not None else wall_time_ns, f["latitude"], f["longitude"],
            f["altitude"], f.get("h_acc_m"), f.get("v_acc_m"), f.get("east_north_sigma_m"), gps_time_utc_ns=gps_ns,
            speed_mps=f.get("speed_mps"), course_deg=f.get("course_deg"), fix_quality=f["fix_quality"],
            satellites=f.get("satellites", 0), hdop=f.get("hdop"), vdop=f.get("vdop"))


class EpochFixes:
    """Checksum-valid sentences → one fix per receiver epoch, handed to ``on_fix(epoch, fix)``.

    ``counts`` gets ``bad_checksum`` and ``parse_errors`` added up; ``wall_offset_ns()`` [ns] turns
    an epoch's monotonic time into wall time for a fix without a date. With ``fixless`` every flush is
    handed on, ``fix`` None where the epoch gave none, ``epoch`` None where there was none (the
    logger judges privacy per epoch).
    """

    def __init__(self, on_fix, counts: dict, wall_offset_ns=lambda: 0, fixless: bool = False):
        self.on_fix = on_fix
        self.fixless = fixless
        self.counts = counts
        self.wall_offset_ns = wall_offset_ns
        self.epoch: Epoch | None = None
        for key in ("bad_checksum", "parse_errors"):
            counts.setdefault(key, 0)

    def sentence(self, text: str, t_mono_ns: int) -> None:
        """One sentence from its ``$`` on, received at ``t_mono_ns``."""
        if not nmea_checksum_ok(text):
            last = text.rfind("$")
            if last > 0 and nmea_checksum_ok(text[last:]):
                text = text[last:]
            else:
                self.counts["bad_checksum"] += 1
                return
        kind = text[3:6]
        if kind not in FIX_TYPES or text.startswith("$P"):
            return
        if kind in FALLBACK_TYPES:
            if self.epoch is not None:
                self.epoch.fallbacks.append(text)
            return
        try:
            msg = pynmea2.parse(text)
        except (pynmea2.ParseError, ValueError, AttributeError, TypeError):
            self.counts["parse_errors"] += 1
            return
        timestamp = getattr(msg, "timestamp", None)
        key = timestamp.isoformat() if timestamp else ""
        if self.epoch is None or key != self.epoch.time_key:
            self.flush()
            self.epoch = Epoch(key, t_mono_ns)
        try:
            self.epoch.add(msg)
        except (ValueError, TypeError, AttributeError):
            self.counts["parse_errors"] += 1

    def flush(self) -> None:
        """Close the current epoch: its fix, if it has one, goes to ``on_fix``."""
        if self.epoch is None:
            if self.fixless:
                self.on_fix(None, None)
            return
        epoch, self.epoch = self.epoch, None
        self.counts["parse_errors"] += epoch.add_fallbacks()
        try:
            fix = epoch.fix(epoch.t_mono_ns + self.wall_offset_ns())
        except (ValueError, TypeError, OverflowError):
            self.counts["parse_errors"] += 1
            fix = None
        if fix is not None or self.fixless:
            self.on_fix(epoch, fix)
