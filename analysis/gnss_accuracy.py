"""A GNSS receiver's accuracy where it stated none: its dilutions of precision times a range error.

A fix's error is the geometry of its satellites (the dilution of precision) times the error of
each satellite's range (the user-equivalent range error, σ_range): horizontal 2D RMS
h_acc = HDOP · σ_range, vertical v_acc = VDOP · σ_range. A u-blox 7 sends HDOP (GGA) and VDOP (GSA)
in every epoch but its own error estimates (GST) only when asked, so a log from a receiver never
asked has the geometry and no accuracy; without an accuracy the gradient could not weigh GPS
altitude at all. σ_range comes from the drive's own fixes that state both an accuracy and a
dilution (the same receiver's ranges on the same day), else from the receiver class's datasheet.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

DATASHEET_RANGE_SIGMA_M = 3.0
"""u-blox 7 (the logger's receiver class): 2.5 m CEP horizontal in open sky (datasheet); a CEP is
1.1774 σ of each axis, so a 2D RMS of 2.5 · √2 / 1.1774 = 3.0 m at an open sky's HDOP of about 1."""
MIN_FIXES_FOR_DRIVE_RANGE = 30
"""Samples stating both HDOP and h_acc needed to take σ_range from the drive (the signals table's
rows: 3 s of fixes at its 10 Hz, 30 s of a 1 Hz receiver's own log)."""
DOP_COLUMNS = {"gps_h_acc_m": "gps_hdop", "gps_v_acc_m": "gps_vdop"}


def _column(frame: pd.DataFrame, name: str) -> np.ndarray | None:
    return frame[name].to_numpy(dtype=float) if name in frame.columns else None


def range_sigma_m(frame: pd.DataFrame) -> tuple[float, str]:
    """σ_range [m] and where it came from: the median of h_acc / HDOP over the drive's samples
    with both, else the datasheet's."""
    h_acc, hdop = _column(frame, "gps_h_acc_m"), _column(frame, "gps_hdop")
    if h_acc is not None and hdop is not None:
        both = np.isfinite(h_acc) & np.isfinite(hdop) & (hdop > 0)
        if both.sum() >= MIN_FIXES_FOR_DRIVE_RANGE:
            return float(np.median(h_acc[both] / hdop[both])), "the drive's fixes stating both (h_acc / HDOP)"
    return DATASHEET_RANGE_SIGMA_M, "a u-blox 7's datasheet (2.5 m CEP)"


def with_dop_accuracy(frame: pd.DataFrame) -> tuple[pd.DataFrame, str | None]:
    """``frame`` with ``gps_h_acc_m`` / ``gps_v_acc_m`` filled as DOP · σ_range on the fixes that
    state a dilution and no accuracy, and a note saying so; ``frame`` itself and None where no fix
    lacks an accuracy its dilution could give."""
    altitude = _column(frame, "gps_altitude_m")
    if altitude is None:
        return frame, None
    fill = {}
    for accuracy_name, dop_name in DOP_COLUMNS.items():
        dop = _column(frame, dop_name)
        if dop is None:
            continue
        accuracy = _column(frame, accuracy_name)
        accuracy = np.full(len(frame), np.nan) if accuracy is None else accuracy
        missing = np.isfinite(altitude) & ~np.isfinite(accuracy) & np.isfinite(dop) & (dop > 0)
        if missing.any():
            fill[accuracy_name] = (missing, dop, accuracy)
    if not fill:
        return frame, None
    sigma, source = range_sigma_m(frame)
    out = frame.assign(**{name: np.where(missing, dop * sigma, accuracy)
                          for name, (missing, dop, accuracy) in fill.items()})
    share = max(int(missing.sum()) for missing, _, _ in fill.values()) / max(int(np.isfinite(altitude).sum()), 1)
    percent = f"{100 * share:.0f}" if share >= 0.01 else f"{100 * share:.1g}"
    names = " and ".join({"gps_h_acc_m": "horizontal", "gps_v_acc_m": "vertical"}[n] for n in fill)
    return out, (f"GPS {names} accuracy on {percent} % of the fixes from the receiver's dilution of "
                 f"precision (it sent no GST) times a range error of {sigma:.1f} m from {source}")
