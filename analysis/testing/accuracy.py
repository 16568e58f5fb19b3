"""The accuracy matrix's unit of work: one seeded virtual drive through the real analysis
(MCAP log -> ingest -> kinematics -> gradient, then mass with each gradient), scored against the
drive's truth (``tools/bench.py accuracy``, ``docs/estimation.md``).

Gradient errors are taken at the log's samples against the true gradient at the same time, then
averaged per 10 m bin of true distance, so a wrong distance scale (wheel speed) counts as the
error it causes. Bins are grouped by what the road is there: ``outside`` (at grade or on an
embankment), ``cutting``, ``bridge``, ``tunnel``.
"""

from __future__ import annotations

import dataclasses
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from haulprofile.analysis.virtual_truck.truth import GRID_SPACING_M, truth_grid

METHODS = {"fusion": "gradient_pct", "baro": "gradient_baro_pct", "map": "gradient_map_pct",
           "smoother": "gradient_smooth_pct", "flat": "gradient_flat_pct"}
"""Method name -> gradient column. ``fusion`` is the paper's (8): the default run's
``gradient_pct``, or the run with ``gradient_method="paper"`` where that exists; ``smoother`` is
used when the gradient stage writes it (by default or with ``gradient_method="smoother"``); ``flat``
(0 %) only where nothing measures a height (``can-only``)."""
CATEGORIES = {"outside": ("at grade", "embankment"), "cutting": ("cutting",), "bridge": ("bridge",),
              "tunnel": ("tunnel",)}
MIN_BINS = 5
MIN_SEGMENT_S = 120.0
MASS_KEYS = ("mass_ls_kg", "mass_rls_kg", "mass_kg", "mass_kg_weighed")
MISMATCH = {"rolling_resistance_coefficient": 0.15, "drag_coefficient": 0.10}
MISMATCH_ETA = 0.02
SENSOR_SETS = ("full", "no-baro", "no-imu", "gps+can", "can-only")
"""The sensor sets each drive is analysed with (`gradient.sensor_sets`): the full log, and the
same log with the missing sensors' columns taken out."""
FLAT = "flat"
"""The gradient of a log with no height source at all: a flat road (``can-only``)."""
STD_COLUMNS = {"smoother": "gradient_smooth_std_pct"}
"""Method -> its per-bin gradient standard deviation [%-pt], scored for coverage."""


@dataclass(frozen=True)
class Case:
    """One drive of the matrix: a shipped scenario cut to about ``length_m`` (0 = whole),
    optionally with a ``stop_s`` stop added halfway along the first section of 3 km or more (a
    trailer change place), at a realism level, with a DEM format (``hgt3``, ``hgt1``, ``geotiff``)."""

    scenario: str
    level: str
    seed: int
    length_m: float = 0.0
    stop_s: float = 0.0
    dem: str = "hgt3"

    @property
    def name(self) -> str:
        return f"{self.scenario}/{self.level}/seed{self.seed}/{self.dem}"


def case_scenario(case: Case):
    """The shipped scenario, cut and with the added stop."""
    from haulprofile.analysis.virtual_truck.scenario import load_scenario
    scenario = load_scenario(case.scenario)
    sections, total, added = [], 0.0, case.stop_s <= 0
    for section in scenario.route.section:
        if case.length_m and total >= case.length_m:
            break
        if case.length_m and total + section.length_m > case.length_m + 1000.0:
            section = dataclasses.replace(section, length_m=max(case.length_m - total, 1000.0))
        total += section.length_m
        if not added and section.length_m >= 3000 and section.stop_s == 0:
            half = section.length_m / 2
            sections.append(dataclasses.replace(section, length_m=half, stop_s=case.stop_s))
            section, added = dataclasses.replace(section, length_m=section.length_m - half), True
        sections.append(section)
    tunnels = tuple(t for t in scenario.tunnel if t.start_m + t.length_m <= total)
    route = dataclasses.replace(scenario.route, section=tuple(sections))
    return dataclasses.replace(scenario, route=route, tunnel=tunnels)


def mismatched_vehicle(vehicle, rng: np.random.Generator):
    """The vehicle as a datasheet would give it: c_r +-15 %, c_d +-10 %, eta +-0.02 (random signs)."""
    changes = {name: getattr(vehicle, name) * (1 + rng.choice([-1, 1]) * share) for name, share in MISMATCH.items()}
    changes["driveline_efficiency"] = vehicle.driveline_efficiency + rng.choice([-1, 1]) * MISMATCH_ETA
    return dataclasses.replace(vehicle, **changes)


def _true_bin_means(signals, virtual, column: str):
    """Per 10 m bin of true distance: the mean of ``column`` over the moving samples, and the
    number of samples (0: none)."""
    truth = virtual.truth
    grid = truth_grid(virtual)
    time_s = signals["time_s"].to_numpy(float)
    distance = np.interp(time_s, truth["time_s"], truth["distance_m"])
    speed = np.interp(time_s, truth["time_s"], truth["speed_mps"])
    estimate = signals[column].to_numpy(float)
    ok = np.isfinite(estimate) & (speed > 1.0)
    index = np.floor(distance[ok] / GRID_SPACING_M).astype(int)
    inside = index < len(grid)
    index, values = index[inside], estimate[ok][inside]
    count = np.bincount(index, minlength=len(grid))
    total = np.bincount(index, weights=values, minlength=len(grid))
    with np.errstate(invalid="ignore", divide="ignore"):
        return total / count, count, grid


def gradient_errors(signals, virtual, column: str) -> dict:
    """RMSE [%-pt] of a gradient column per bin category (None where too few bins)."""
    mean, count, grid = _true_bin_means(signals, virtual, column)
    error = mean - grid["gradient_pct"].to_numpy()
    out = {}
    for name, kinds in CATEGORIES.items():
        pick = (count > 0) & np.isin(grid["structure"], kinds)
        out[name] = float(np.sqrt(np.mean(error[pick] ** 2))) if pick.sum() >= MIN_BINS else None
    return out


def gradient_coverage(signals, virtual, column: str, std_column: str) -> float | None:
    """Share of the 10 m bins whose true gradient lies inside the stated ±2σ of ``std_column``."""
    mean, count, grid = _true_bin_means(signals, virtual, column)
    std, _, _ = _true_bin_means(signals, virtual, std_column)
    pick = (count > 0) & np.isfinite(std)
    if pick.sum() < MIN_BINS:
        return None
    return float(np.mean(np.abs(mean[pick] - grid["gradient_pct"].to_numpy()[pick]) <= 2 * std[pick]))


def _scored_segments(segments, truth):
    """(segment index, segment, true mass) of the segments of >= MIN_SEGMENT_S within one true mass."""
    time_s, mass = truth["time_s"].to_numpy(), truth["mass_kg"].to_numpy()
    for j, segment in enumerate(segments):
        if segment["end_s"] - segment["start_s"] < MIN_SEGMENT_S:
            continue
        inside = (time_s >= segment["start_s"]) & (time_s <= segment["end_s"])
        if not inside.any() or np.ptp(mass[inside]) > 0:
            continue
        yield j, segment, float(mass[inside][0])


def mass_errors(signals, truth, vehicle, column: str, gradient_posteriors=()) -> dict:
    """Relative errors of each confident segment's mass when the gradient is ``column``: LS and
    RLS where the LS is ``ok``; ``mass_kg`` (the joint estimate, else LS) wherever it is given,
    and in ``mass_kg_within_2_sigma`` whether the truth lies inside its stated ±2σ, in ``mass_kg_z``
    its error over its stated σ, (m̂ - m) / σ (N(0, 1) where σ is honest). The same for
    ``mass_kg_weighed``: with the first scored segment weighed (`--known-mass`, its true mass),
    the other segments' errors, the torque gain calibrated."""
    from haulprofile.analysis.mass import estimate_mass
    frame = signals.assign(gradient_pct=signals[column])
    if column != METHODS["smoother"] and "gradient_mass_pct" in frame.columns:
        frame = frame.drop(columns=[c for c in ("gradient_mass_pct", "gradient_mass_std_pct") if c in frame.columns])
    result = estimate_mass(frame, vehicle, gradient_posteriors=gradient_posteriors)
    out = {key: [] for key in MASS_KEYS} | {"mass_kg_within_2_sigma": [], "mass_kg_z": [], "mass_kg_weighed": [],
                                           "mass_kg_weighed_within_2_sigma": [], "mass_kg_weighed_z": []}
    scored = list(_scored_segments(result.segments, truth))
    for _, segment, true in scored:
        for key in MASS_KEYS:
            confident = segment["status"] == "ok" if key != "mass_kg" else True
            if confident and segment.get(key) is not None:
                out[key].append(float(segment[key] / true - 1))
        sigma = segment.get("mass_uncertainty_kg")
        if segment.get("mass_kg") is not None and sigma is not None and np.isfinite(sigma):
            out["mass_kg_within_2_sigma"].append(bool(abs(segment["mass_kg"] - true) <= 2 * sigma))
            out["mass_kg_z"].append(float((segment["mass_kg"] - true) / sigma) if sigma > 0 else None)
    # a weighing calibrates the joint fit: its segment needs a joint mass (not the LS standing in)
    weighed = [(j, true) for j, segment, true in scored if segment.get("mass_kg") is not None
               and segment.get(f"mass_{segment.get('mass_regressor')}_kg") is not None]
    if len(scored) >= 2 and weighed:
        first, known = weighed[0]
        calibrated = estimate_mass(frame, vehicle, known_masses={first: known}, gradient_posteriors=gradient_posteriors)
        for j, segment, true in _scored_segments(calibrated.segments, truth):
            sigma = segment.get("mass_uncertainty_kg")
            if j == first or segment.get("mass_kg") is None or sigma is None or not np.isfinite(sigma):
                continue
            out["mass_kg_weighed"].append(float(segment["mass_kg"] / true - 1))
            out["mass_kg_weighed_within_2_sigma"].append(bool(abs(segment["mass_kg"] - true) <= 2 * sigma))
            out["mass_kg_weighed_z"].append(float((segment["mass_kg"] - true) / sigma) if sigma > 0 else None)
    return out


def _method_samples(signals, dem_dir: Path, method: str) -> dict | None:
    """The gradient columns with ``GradientSettings(gradient_method=method)``, if the settings
    offer that choice (the estimator of the issue "Estimation that holds on real terrain")."""
    from haulprofile.analysis.dem import open_dem
    from haulprofile.analysis.errors import UserError
    from haulprofile.analysis.gradient import GradientSettings, estimate_gradient
    if "gradient_method" not in {f.name for f in dataclasses.fields(GradientSettings)}:
        return None
    try:
        settings = GradientSettings(gradient_method=method)
        return estimate_gradient(signals, open_dem(dem_dir), settings).samples
    except (TypeError, ValueError, UserError):
        return None


def _gradient_columns(signals, dem_dir: Path):
    """The default run's columns, with the paper's fusion (8) as ``gradient_pct`` and the smoother's
    ``gradient_smooth_pct`` added when the gradient stage can be asked for them by name."""
    paper = _method_samples(signals, dem_dir, "paper")
    if paper is not None and METHODS["fusion"] in paper:
        signals = signals.assign(**{METHODS["fusion"]: paper[METHODS["fusion"]]})
    if METHODS["smoother"] not in signals.columns:
        smooth = _method_samples(signals, dem_dir, "smoother")
        if smooth is not None and METHODS["smoother"] in smooth:
            signals = signals.assign(**{METHODS["smoother"]: smooth[METHODS["smoother"]]})
    return signals


def sensor_set_signals(base, set_name: str):
    """``base`` (signals after the kinematics stage) as the kinematics stage of a logger with only
    ``set_name``'s sensors gives them: the other sensors' columns out, the speed the wheel's again
    and its scale measured on the track that is left (none without GPS: a logger without it never
    has the track's speed)."""
    from haulprofile.analysis.gradient.sensor_sets import without_sensors
    from haulprofile.analysis.kinematics import add_kinematics
    frame = without_sensors(base, set_name)
    add_kinematics(frame)
    return frame


def _sensor_set_columns(base, dem_dir: Path, set_name: str, virtual):
    """The signals of ``base`` as a logger with only ``set_name``'s sensors gives them, with the
    gradient columns the estimator makes of them as the gradient stage does (the force balance as
    the accelerometer where there is neither IMU nor barometer; ``gradient_pct`` = the paper's fusion (8) where it can
    run). The kinematics are made again on what is left (`sensor_set_signals`). A log with no height
    source (``can-only``) is given the true mass per sample, as a weighing at every load change would
    give it, and scored against the flat road too. Returns the signals and the gradient's posteriors
    (`GradientResult.posteriors`)."""
    from haulprofile.analysis.dem import open_dem
    from haulprofile.analysis.errors import UserError
    from haulprofile.analysis.gradient.force_balance import estimate_gradient_for_log, estimate_gradient_force_balance
    from haulprofile.analysis.gradient.sensor_sets import sensors_present
    frame = sensor_set_signals(base, set_name)
    given = None
    if "gps" not in sensors_present(frame):
        given = np.interp(frame["time_s"], virtual.truth["time_s"], virtual.truth["mass_kg"])
        frame = frame.assign(**{METHODS[FLAT]: np.zeros(len(frame))})
    try:
        if given is None:
            result = estimate_gradient_for_log(frame, open_dem(dem_dir), vehicle=virtual.vehicle)
        else:
            result = estimate_gradient_force_balance(frame, open_dem(dem_dir), virtual.vehicle, mass_kg=given)
    except UserError:
        return frame, ()
    samples = result.samples
    frame = frame.assign(**samples)
    return frame.assign(**{METHODS["fusion"]: samples["gradient_paper_pct"]}), result.posteriors


def score(signals, virtual, vehicles, mass: bool = True, gradient_posteriors=()) -> dict:
    """Gradient errors (and the per-bin σ's coverage) and mass errors of every method present
    (no mass errors where the mass was given)."""
    methods = {name: column for name, column in METHODS.items() if column in signals.columns}
    return {
        "gradient": {name: gradient_errors(signals, virtual, column) for name, column in methods.items()},
        "gradient_within_2_sigma": {name: gradient_coverage(signals, virtual, METHODS[name], std)
                                    for name, std in STD_COLUMNS.items() if std in signals.columns},
        "mass": {kind: {name: mass_errors(signals, virtual.truth, vehicle, column, gradient_posteriors) for name, column in methods.items()}
                 for kind, vehicle in vehicles.items()} if mass else {},
    }


def analysed_to_gradient(virtual, root: Path, dem: str = "hgt3"):
    """The pipeline's context after the gradient stage on a virtual drive's MCAP log and DEM
    (``dem``: ``hgt3``, ``hgt1`` or ``geotiff``), written under ``root`` (logs/, dem/, out/)."""
    from haulprofile.analysis.pipeline import RunContext, run
    from haulprofile.analysis.virtual_truck.dem import write_dem
    from haulprofile.analysis.virtual_truck.mcap_log import write_mcap
    write_dem(virtual, root / "dem", arc_seconds=1 if dem == "hgt1" else 3, fmt="geotiff" if dem == "geotiff" else "hgt")
    write_mcap(virtual, root / "logs" / f"{virtual.scenario.name}.mcap")
    ctx = RunContext(inputs=[root / "logs"], out_dir=root / "out", vehicle=virtual.vehicle,
                     dem_dir=root / "dem", say=lambda _msg: None, options={"output": {"figures": False}})
    run(ctx, until="gradient")
    return ctx


def run_case(case: Case, sensor_sets: tuple[str, ...] = SENSOR_SETS) -> dict:
    """Drive, log, analyse and score one case with each sensor set; a dict of plain values (for
    a process pool). The ``full`` set's figures are at the top level as before, every set's under
    ``sensor_sets``."""
    from haulprofile.analysis.virtual_truck.truck import drive
    scenario = case_scenario(case)
    virtual = drive(scenario, seed=case.seed, realism=case.level)
    rng = np.random.default_rng(case.seed)
    vehicles = {"exact": virtual.vehicle, "datasheet": mismatched_vehicle(virtual.vehicle, rng)}
    scores = {}
    with tempfile.TemporaryDirectory(prefix="haulprofile-accuracy-") as tmp:
        root = Path(tmp)
        ctx = analysed_to_gradient(virtual, root, case.dem)
        base = ctx.signals.drop(columns=[c for c in ctx.results.gradient.samples if c in ctx.signals.columns])
        for set_name in sensor_sets:
            if set_name == "full":
                signals, posteriors = _gradient_columns(ctx.signals, root / "dem"), ctx.results.gradient.posteriors
            else:
                signals, posteriors = _sensor_set_columns(base, root / "dem", set_name, virtual)
            scores[set_name] = score(signals, virtual, vehicles, mass=set_name != "can-only", gradient_posteriors=posteriors)
    grid = truth_grid(virtual)
    full = scores.get("full", {"gradient": {}, "gradient_within_2_sigma": {}, "mass": {}})
    return {
        "case": dataclasses.asdict(case), "name": case.name,
        "km": float(virtual.road.length_m / 1000), "minutes": float(virtual.duration_s / 60),
        "structures_m": {kind: float((grid["structure"] == kind).sum() * GRID_SPACING_M)
                         for kind in ("cutting", "embankment", "bridge", "tunnel")},
        **full, "sensor_sets": scores,
        "injected": {k: v for k, v in virtual.injected.items() if k != "realism"},
    }
