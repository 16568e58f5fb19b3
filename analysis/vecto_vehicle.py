"""VECTO vehicles (``.vecto`` job files and the ``.vveh``, ``.vgbx``, ``.veng``, ``.vfld`` files
they name) as our vehicle file, as far as the longitudinal parameters go.

VECTO's files are JSON (``{"Header": …, "Body": …}``, UTF-8 with a byte-order mark) and CSV
(the full-load curve). What is taken, from VECTO's own field names:

* ``.vveh``: ``CurbWeight`` + ``CurbWeightExtra`` [kg] → ``curb_mass_kg``; ``MassMax`` (t in
  current files, kg in old ones: below 100 it is t) minus the curb mass → ``max_payload_kg``;
  ``Cd``, ``CrossSecArea`` [m²] (from file version 7 only their product ``CdA``: then a nominal
  10 m² and c_d = CdA / 10, the product being all that equation (1) uses); ``rdyn`` [mm] (old
  files ``WheelsDiaEff`` [m], the diameter) →
  ``wheel_radius_m``; the axles' ``RRCISO`` and ``FzISO`` [N] with ``AxleWeightShare`` → the
  rolling resistance coefficient as VECTO forms it, c_r = Σ share_i · RRC_i · (F_z,i / FzISO_i)^(β−1),
  β = 0.9, F_z,i = share_i · (curb + ``Loading``) · g. A declaration-mode file has no shares
  (VECTO takes them, and a generic trailer, from its segment table): the axles' RRCISO are then
  averaged, and the result says so.
* ``.vgbx``: ``Gears[0].Ratio`` is the axle, the others the gears → ``axle_ratio``, ``gear_ratios``.
* ``.veng`` + ``.vfld``: ``IdlingSpeed`` [rpm], the full-load curve's highest speed and power →
  ``[engine]``; its highest torque → ``engine_reference_torque_nm`` **[choice: J1939's reference
  torque (SPN 544) is the engine's peak torque]**.
* not in VECTO's files as one number: the driveline efficiency (VECTO has loss maps): 0.93, the
  vehicle file's documented default.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from .errors import UserError

SUFFIXES = {".vecto", ".vveh"}
GRAVITY_MPS2 = 9.81
RRC_BETA = 0.9
"""VECTO's exponent of the rolling resistance's load dependence (RRC ∝ F_z^(β−1))."""
DEFAULT_DRIVELINE_EFFICIENCY = 0.93
NOMINAL_FRONTAL_AREA_M2 = 10.0
"""Frontal area put beside VECTO's c_d·A where a file gives only the product [m²]."""
NO_FILE = "<NOFILE>"


class VectoFileError(UserError):
    pass


def _body(path: Path) -> dict:
    try:
        data = json.loads(path.read_text(encoding="utf-8-sig"))
    except FileNotFoundError:
        raise VectoFileError(f"VECTO file {path} not found") from None
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise VectoFileError(f"{path}: cannot read as a VECTO JSON file ({exc})") from None
    body = data.get("Body") if isinstance(data, dict) else None
    if not isinstance(body, dict):
        raise VectoFileError(f"{path}: not a VECTO file (no \"Body\" object)")
    return body


def _number(body: dict, key: str, path: Path, default=None) -> float:
    value = body.get(key, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        if default is not None and key not in body:
            return float(default)
        raise VectoFileError(f"{path}: \"{key}\" is missing or not a number ({value!r})")
    return float(value)


def _named(job: Path, body: dict, key: str) -> Path | None:
    name = body.get(key)
    if not isinstance(name, str) or not name or name == NO_FILE:
        return None
    return job.parent / name.replace("\\", "/")


def rolling_resistance(axles: list[dict], total_mass_kg: float, path: Path) -> tuple[float, str | None]:
    """c_r of the axles (VECTO's formula with weight shares; their mean RRCISO without), and a note."""
    rrc = [_number(a, "RRCISO", path) for a in axles]
    shares = [float(a.get("AxleWeightShare") or 0.0) for a in axles]
    if axles and all(s > 0 for s in shares) and abs(sum(shares) - 1.0) < 0.01:
        fz_iso = [_number(a, "FzISO", path) for a in axles]
        value = sum(s * c * (s * total_mass_kg * GRAVITY_MPS2 / f) ** (RRC_BETA - 1)
                    for s, c, f in zip(shares, rrc, fz_iso))
        return float(value), None
    if not rrc:
        raise VectoFileError(f"{path}: no axles in \"AxleConfig\"")
    return float(np.mean(rrc)), ("no axle weight shares (a declaration-mode file): rolling resistance is the mean "
                                 "of the axles' RRCISO, without VECTO's load correction or its generic trailer")


def full_load_curve(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Engine speed [rpm] and full-load torque [Nm] of a ``.vfld`` (header row, then speed, torque, …)."""
    try:
        rows = list(csv.reader(path.read_text(encoding="utf-8-sig").splitlines()))[1:]
        values = np.array([[float(r[0]), float(r[1])] for r in rows if len(r) >= 2 and r[0].strip()])
    except (OSError, ValueError, UnicodeDecodeError) as exc:
        raise VectoFileError(f"{path}: cannot read as a VECTO full-load curve ({exc})") from None
    if values.ndim != 2 or len(values) < 2:
        raise VectoFileError(f"{path}: a full-load curve needs at least two rows of speed and torque")
    return values[:, 0], values[:, 1]


def vehicle_tables(path: str | Path) -> tuple[dict, list[str]]:
    """Our vehicle-file tables (``vehicle_from_dict`` input) of a VECTO job or vehicle file, and
    notes on what was approximated."""
    path = Path(path)
    if path.suffix.lower() not in SUFFIXES:
        raise VectoFileError(f"{path}: a VECTO vehicle is a .vecto job or a .vveh vehicle file")
    job = _body(path) if path.suffix.lower() == ".vecto" else {}
    vveh = _named(path, job, "VehicleFile") if job else path
    if vveh is None:
        raise VectoFileError(f"{path}: the job names no \"VehicleFile\"")
    body = _body(vveh)
    curb = _number(body, "CurbWeight", vveh) + _number(body, "CurbWeightExtra", vveh, 0.0)
    mass_max = _number(body, "MassMax", vveh)
    mass_max_kg = mass_max * 1000.0 if mass_max < 100.0 else mass_max
    if "rdyn" in body:
        radius = _number(body, "rdyn", vveh) / 1000.0
    else:
        radius = _number(body, "WheelsDiaEff", vveh) / 2.0
    axles = (body.get("AxleConfig") or {}).get("Axles") or []
    c_r, note = rolling_resistance(axles, curb + _number(body, "Loading", vveh, 0.0), vveh)
    notes = [note] if note else []
    if "CdA" in body:  # file version 7 on: the product only, which is all equation (1) uses
        drag_area = _number(body, "CdA", vveh)
        drag, area = round(drag_area / NOMINAL_FRONTAL_AREA_M2, 9), NOMINAL_FRONTAL_AREA_M2
        notes.append(f"VECTO gives c_d·A = {drag_area:g} m² only: frontal_area_m2 {area:g} (nominal), "
                     f"drag_coefficient {drag:.4g}, so that their product is VECTO's")
    else:
        drag, area = _number(body, "Cd", vveh), _number(body, "CrossSecArea", vveh)
    vehicle = {"name": f"{path.stem} (from VECTO {path.name})", "curb_mass_kg": curb,
               "drag_coefficient": drag, "frontal_area_m2": area,
               "rolling_resistance_coefficient": c_r, "wheel_radius_m": radius,
               "driveline_efficiency": DEFAULT_DRIVELINE_EFFICIENCY}
    notes.append(f"driveline_efficiency {DEFAULT_DRIVELINE_EFFICIENCY} (VECTO has loss maps, not one efficiency)")
    tables = {"vehicle": vehicle, "load": {"max_payload_kg": max(mass_max_kg - curb, 0.0)}}
    gearbox = _named(path, job, "GearboxFile")
    if gearbox is not None:
        gears = [_number(g, "Ratio", gearbox) for g in _body(gearbox).get("Gears") or []]
        if len(gears) >= 2:
            vehicle["axle_ratio"], vehicle["gear_ratios"] = gears[0], gears[1:]
    engine_file = _named(path, job, "EngineFile")
    if engine_file is not None:
        engine = _body(engine_file)
        curve = _named(engine_file, engine, "FullLoadCurve")
        tables["engine"] = {"idle_speed_rpm": _number(engine, "IdlingSpeed", engine_file)}
        if curve is not None:
            speed, torque = full_load_curve(curve)
            vehicle["engine_reference_torque_nm"] = float(torque.max())
            tables["engine"]["max_speed_rpm"] = float(speed.max())
            tables["engine"]["max_power_w"] = float(np.max(speed * torque) * 2.0 * np.pi / 60.0)
    return tables, notes


def vehicle_toml(path: str | Path) -> str:
    """Our vehicle file (TOML text) of a VECTO job or vehicle file, its notes as comments on top."""
    import tomli_w

    tables, notes = vehicle_tables(path)
    header = [f"# Converted from the VECTO file {Path(path).name} by haulprofile."] + [f"# {n}" for n in notes]
    return "\n".join(header) + "\n\n" + tomli_w.dumps(tables)
