"""The mass stage: `estimate_mass` per segment between stops, ``mass_kg`` and each method's
column added in memory; `write_mass` is its part of the output step (``mass.png``), `mass_chapter`
its report chapter."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from ..errors import UserError
from ..stage import Stage
from . import MassResult, estimate_mass
from .chapter import TITLE, mass_chapter
from .figure import draw_estimates
from .joint import JointSettings
from .regression import FilterSettings
from .segments import SegmentSettings


@dataclass(frozen=True)
class MassOptions:
    """Options of the mass stage."""

    filter: FilterSettings = field(default_factory=FilterSettings)
    """Thresholds of the data filter [SI units]."""
    segments: SegmentSettings = field(default_factory=SegmentSettings)
    """Segmentation at stops and the estimators' parameters (forgetting factor, damping)."""
    joint: JointSettings = field(default_factory=JointSettings)
    """The joint fit of all segments' masses with c_r and c_d·A, and its uncertainty terms."""
    weighed_masses_kg: tuple[tuple[int, float], ...] = ()
    """Weighed total masses [kg] as (segment index from 0, kg) pairs: they calibrate the engine
    torque gain for every segment."""
    known_mass_kg: float | None = None
    """A known constant total mass [kg]: written as ``mass_kg`` instead of estimating one."""
    keep_existing: bool = False
    """Keep a ``mass_kg`` column the input already has instead of estimating it again."""
    true_mass_kg: tuple[float, ...] | None = None
    """The weighed total mass [kg], one value or one per segment, drawn in the figure."""


@dataclass
class GivenMass:
    """The mass stage's result for a known total mass (``known_mass_kg``): nothing estimated."""

    mass_kg: float
    joint = None
    drive = None

    def summary(self) -> dict:
        return {"given_mass_kg": self.mass_kg, "segments": [], "samples_used": 0,
                "notes": [f"the total mass was given as {self.mass_kg:.0f} kg for the whole drive (known_mass_kg), "
                          f"not estimated"]}


def mass_stage(ctx) -> MassResult | GivenMass | None:
    """Add ``mass_kg`` (the joint estimate where confident, else LS; and ``mass_ls_kg``,
    ``mass_rls_kg``, ``mass_lm_kg``) to ``ctx.signals``.

    Parameters
    ----------
    ctx : pipeline.RunContext
        Reads ``signals`` (time_s [s], speed_mps [m/s], accel_mps2 [m/s²], gradient_pct [%],
        engine_torque_nm [Nm], engine_speed_rpm [rpm]), ``vehicle`` and ``options.mass`` (`MassOptions`).

    References
    ----------
    Paper §2.2.2, equations (9)-(14).
    """
    options: MassOptions = ctx.options.mass
    frame = ctx.signals
    if options.known_mass_kg is not None:
        if not options.known_mass_kg > 0:
            raise UserError(f"known_mass_kg must be a positive mass in kg, got {options.known_mass_kg}")
        frame["mass_kg"] = float(options.known_mass_kg)
        return GivenMass(float(options.known_mass_kg))
    if options.keep_existing and "mass_kg" in frame.columns and frame["mass_kg"].notna().any():
        return None
    if ctx.vehicle is None:
        ctx.skip("mass", "needs a vehicle file")
        return None
    try:
        gradient = ctx.results.get("gradient")
        result = estimate_mass(frame, ctx.vehicle, options.filter, options.segments, options.joint,
                               dict(options.weighed_masses_kg), getattr(gradient, "posteriors", ()))
    except UserError as exc:
        ctx.skip("mass", str(exc))
        return None
    for note in result.notes:
        ctx.say(f"mass: {note}")
    for name, values in result.columns.items():
        frame[name] = values
    for segment in result.segments:
        if segment["status"] != "ok":
            ctx.say(f"mass: segment {segment['start_s']:.0f}-{segment['end_s']:.0f} s: no confident mass "
                    f"({segment['reason']})")
    result.drive = frame[[c for c in ("time_s", "reported_mass_kg") if c in frame.columns]].copy()
    result.true_mass_kg = options.true_mass_kg
    return result


def write_mass(result: MassResult, directory: Path, figures: bool = True) -> list[str]:
    """With ``figures``, ``mass.png`` (each method over time beside the CAN estimate); returns the names."""
    if not figures or result.drive is None:
        return []
    return [draw_estimates(result.drive, result, directory / "mass.png",
                           list(result.true_mass_kg) if result.true_mass_kg is not None else None).name]


STAGE = Stage("mass", MassOptions, mass_stage, write=write_mass, files=("mass.png",), chapter=mass_chapter,
              title=TITLE, reads_vehicle=True, required=True)
