"""The engine torque that reaches the driveline: the reported torque less what the accessories take,
where the engine says so (J1939 EEC3, SPN 2978).

J1939-71 defines the actual engine torque (SPN 513) as the indicated torque, the friction
included; the nominal friction (SPN 514) as the basic engine's own losses (friction, pumping, the
fuel, oil and coolant pumps); and the estimated parasitic losses (SPN 2978) as the torque the
accessories take (cooling fan, air compressor, air conditioning), not in SPN 514 unless sent as
0xFB. Many engines report SPN 513 net of SPN 514 instead (it goes negative in a fuel cut,
`gradient.force_balance.reports_engine_drag`); both ways the accessories' torque is still in it,
and what turns the gearbox is the report less SPN 2978. SPN 514 is not taken off: where the
report is net (the virtual truck; any engine whose report goes negative) it is already out; an
engine whose report is the indicated torque would need it taken off too, which is not done here
(``docs/estimation.md``).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

PARASITIC_COLUMN = "engine_parasitic_torque_nm"
SUBTRACTED = "accessory torque from J1939 EEC3 subtracted"
REPORTED = "reported engine torque (no accessory torque in the log)"


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


def driveline_torque_nm(frame: pd.DataFrame) -> np.ndarray:
    """The engine torque [Nm] that reaches the driveline: ``engine_torque_nm`` less the accessories'
    torque where the log reports it (`parasitic_torque_nm`), else ``engine_torque_nm`` as it is."""
    torque = frame["engine_torque_nm"].to_numpy(dtype=float)
    parasitic = parasitic_torque_nm(frame)
    return torque if parasitic is None else torque - parasitic


def torque_used(frame: pd.DataFrame) -> str:
    """Which torque `driveline_torque_nm` gives, for summaries."""
    return SUBTRACTED if parasitic_torque_nm(frame) is not None else REPORTED
