"""The engine torque that reaches the driveline: the reported torque in its net form, less what the
accessories take where the engine says so (J1939 EEC3, SPN 2978).

J1939-71 defines the actual engine torque (SPN 513) as the indicated torque, the friction
included, never below zero; the nominal friction (SPN 514) as the basic engine's own losses
(friction, pumping, the fuel, oil and coolant pumps); and the estimated parasitic losses (SPN 2978)
as the torque the accessories take (cooling fan, air compressor, air conditioning), not in SPN 514
unless sent as 0xFB. Many engines report SPN 513 net of SPN 514 instead: it goes negative in a fuel
cut. `torque_report_form` tells the two apart from the drive itself; an indicated report has its
friction taken off (SPN 514), so both forms give the torque at the flywheel, and what turns the
gearbox is that less SPN 2978.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from .runs import true_runs

PARASITIC_COLUMN = "engine_parasitic_torque_nm"
FRICTION_COLUMN = "engine_friction_torque_nm"
SUBTRACTED = "accessory torque from J1939 EEC3 subtracted"
REPORTED = "reported engine torque (no accessory torque in the log)"
FRICTION_SUBTRACTED = "indicated engine torque less its friction (J1939 EEC3 SPN 514)"
NO_FRICTION = "indicated engine torque without its friction in the log (not corrected)"

NET, INDICATED, UNKNOWN = "net", "indicated", "unknown"
FORM_SHARE = 0.01
"""Share of the moving samples that decides the form: below zero (net), or at zero in fuel cuts
(indicated)."""
FUEL_CUT_S = 2.0
"""Shortest run of zero torque while moving taken as a fuel cut: a gear shift's unloaded engine
lasts about a second."""
MOVING_MPS = 1.0


def torque_report_form(frame: pd.DataFrame) -> str:
    """How the log's engine reports SPN 513: ``net`` of its friction where the report goes below zero
    while the wheels motor the engine; ``indicated`` where it never does but sits at exactly zero
    through fuel cuts (runs of `FUEL_CUT_S` or more while moving), as J1939-71 defines it; else
    ``unknown``. The idling torque does not decide: an indicated report carries the friction there,
    but a report offset of a few per cent of the reference (as large as the friction) hides it."""
    if "engine_torque_nm" not in frame.columns or "speed_mps" not in frame.columns:
        return UNKNOWN
    torque = frame["engine_torque_nm"].to_numpy(dtype=float)
    speed = frame["speed_mps"].to_numpy(dtype=float)
    moving = (speed > MOVING_MPS) & np.isfinite(torque)
    if not moving.any():
        return UNKNOWN
    if np.mean(torque[moving] < 0) >= FORM_SHARE:
        return NET
    zero = moving & (torque == 0)
    if np.sum(_long_runs(zero, frame["time_s"].to_numpy(dtype=float), FUEL_CUT_S)) < FORM_SHARE * moving.sum():
        return UNKNOWN
    return INDICATED


def _long_runs(flags: np.ndarray, time_s: np.ndarray, min_s: float) -> np.ndarray:
    """``flags`` kept only in runs that last at least ``min_s``."""
    out = np.zeros(flags.shape, dtype=bool)
    for start, end in true_runs(flags):
        if time_s[end - 1] - time_s[start] >= min_s:
            out[start:end] = True
    return out


def friction_torque_nm(frame: pd.DataFrame) -> np.ndarray | None:
    """The engine's nominal friction [Nm] per sample (SPN 514, held over gaps), or None where the
    log has none or only zeros."""
    if FRICTION_COLUMN not in frame.columns:
        return None
    values = frame[FRICTION_COLUMN].astype(float).ffill().bfill().to_numpy()
    if not np.isfinite(values).any() or np.nanmax(np.abs(values)) == 0:
        return None
    return np.nan_to_num(values)


def parasitic_torque_nm(frame: pd.DataFrame) -> np.ndarray | None:
    """The accessories' torque [Nm] per sample (0 where a sample has none) where the log reports
    one that changes; None where it is missing or constant: engines that count the accessories in
    SPN 514 send a constant 0 %, and any constant is a torque offset, which the joint mass fit has
    its own term for."""
    if PARASITIC_COLUMN not in frame.columns:
        return None
    values = frame[PARASITIC_COLUMN].to_numpy(dtype=float)
    finite = values[np.isfinite(values)]
    if finite.size == 0 or finite.min() == finite.max():
        return None
    return np.nan_to_num(values)


def flywheel_torque_nm(frame: pd.DataFrame) -> np.ndarray:
    """``engine_torque_nm`` in its net form: an indicated report (`torque_report_form`) less the
    engine's friction where the log has it; any other report as it is."""
    torque = frame["engine_torque_nm"].to_numpy(dtype=float)
    if torque_report_form(frame) != INDICATED:
        return torque
    friction = friction_torque_nm(frame)
    return torque if friction is None else torque - friction


def driveline_torque_nm(frame: pd.DataFrame) -> np.ndarray:
    """The engine torque [Nm] that reaches the driveline: the flywheel torque (`flywheel_torque_nm`)
    less the accessories' torque where the log reports it (`parasitic_torque_nm`)."""
    torque = flywheel_torque_nm(frame)
    parasitic = parasitic_torque_nm(frame)
    return torque if parasitic is None else torque - parasitic


def knows_engine_drag(frame: pd.DataFrame) -> bool:
    """Whether `driveline_torque_nm` includes the engine's drag while the wheels motor it: a net
    report, or an indicated one whose friction the log carries."""
    form = torque_report_form(frame)
    return form == NET or (form == INDICATED and friction_torque_nm(frame) is not None)


def torque_used(frame: pd.DataFrame) -> str:
    """Which torque `driveline_torque_nm` gives, for summaries: the accessories' part, and for an
    indicated report its friction's, joined by '; '."""
    said = [SUBTRACTED if parasitic_torque_nm(frame) is not None else REPORTED]
    if torque_report_form(frame) == INDICATED:
        said.insert(0, FRICTION_SUBTRACTED if friction_torque_nm(frame) is not None else NO_FRICTION)
    return "; ".join(said)
