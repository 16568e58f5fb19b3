"""Compile the analysis kernels ahead, in a second process, while the demo logs its drive.

numba compiles each kernel at its first call and keeps it on disk (``cache=True``), so on a fresh
install the first run of the chain spends about a minute compiling. `analyze demo` first logs its
drive through the daemon and the emulated devices, which share one process and so one core, for
about a minute; it starts this module beside it before its own drive (`beside`): the second core
is idle until the logging starts, so the two compiling the virtual truck's kernels at once costs
the demo nothing and the warm-up is done sooner. The warm-up drives a short virtual
route of the same vehicle at the same realism and runs every stage on it with a small cycle pool
and concept search, which compiles and caches the same kernels with the same argument types. The
demo's own run then loads them. A kernel the demo needs while it is still being compiled here is
compiled by the demo too (numba replaces its cache files whole), so a warm-up can only save time;
it runs at the lowest CPU priority and the demo stops it when it is done with it.

Once a warm-up has finished, a stamp named by the package's sources and numba's version says so,
and later demos start none (`needed`).
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import os
import platform
import shutil
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent.parent
"""The installed ``haulprofile`` package (``logger/`` and ``analysis/``)."""

SHORT_ROUTE = {
    "route": {"initial_stop_s": 5.0, "final_stop_s": 20.0,
              "section": [{"length_m": 1500.0, "speed_kmh": 60.0, "stop_s": 40.0},
                          {"length_m": 2500.0, "speed_kmh": 70.0}]},
    "tunnel": [{"start_m": 2200.0, "length_m": 600.0}],
    "payload": {"initial_kg": 6000.0, "after_stop_kg": [2000.0]},
}
"""Four kilometres with a stop that unloads and a tunnel: every stage's paths, in seconds."""

WARMUP_OPTIONS = {"cycle": {"n_candidates": 200, "n_moves": 200, "duration_s": 600.0},
                  "design": {"population": 8, "generations": 2}}
"""Small searches: the kernels' types do not depend on their sizes."""


def fingerprint() -> str:
    """Hash of what the cached kernels depend on: every source file of the package (path, size,
    modification time), Python's and numba's versions."""
    import numba

    digest = hashlib.sha256(f"{platform.python_version()} {numba.__version__}".encode())
    for path in sorted(PACKAGE_DIR.rglob("*.py")):
        stat = path.stat()
        digest.update(f"{path.relative_to(PACKAGE_DIR)} {stat.st_size} {stat.st_mtime_ns}".encode())
    return digest.hexdigest()[:16]


def stamp_path() -> Path:
    """Where a finished warm-up leaves its stamp: numba's cache directory if one is set, else the
    package's own ``__pycache__`` (where numba keeps the kernels)."""
    import numba

    base = Path(numba.config.CACHE_DIR) if numba.config.CACHE_DIR else PACKAGE_DIR / "analysis" / "__pycache__"
    return base / f"haulprofile-warm-{fingerprint()}"


def needed() -> bool:
    """True when no warm-up has finished for these sources since they last changed."""
    try:
        return not stamp_path().exists()
    except OSError:
        return False


def start(scenario, realism: str) -> subprocess.Popen | None:
    """Start a warm-up process for the vehicle of ``scenario`` (`virtual_truck.Scenario`) at
    ``realism`` at the lowest CPU priority, or None when none is needed or one cannot start (a
    warm-up only ever saves time)."""
    if not needed():
        return None
    command = [sys.executable, "-m", "haulprofile.analysis.warmup", "--vehicle", scenario.vehicle,
               "--base-dir", str(Path(scenario.base_dir).resolve()), "--realism", realism]
    try:
        return subprocess.Popen(command, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL, preexec_fn=lambda: os.nice(19))
    except OSError:
        return None


def stop(process: subprocess.Popen | None) -> None:
    """End a warm-up process that is still running (its finished kernels stay cached)."""
    if process is None or process.poll() is not None:
        return
    process.terminate()
    try:
        process.wait(timeout=10)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()


@contextlib.contextmanager
def beside(enabled: bool, scenario, realism: str):
    """A warm-up (`start`) running while the ``with`` block runs, stopped when it ends."""
    process = start(scenario, realism) if enabled else None
    try:
        yield process
    finally:
        stop(process)


def warm(vehicle_name: str, realism: str, work_dir: Path, base_dir: Path = Path(".")) -> None:
    """Drive `SHORT_ROUTE` with ``vehicle_name`` (a shipped example, or a file in ``base_dir`` as
    a scenario names it) at ``realism`` and run every stage on its log (no output step: it holds
    no kernel, and its figures took a quarter of the warm-up)."""
    import datetime as dt

    from .pipeline import STAGES, RunContext, load_inputs, run_stage
    from .virtual_truck import drive, realism_level, scenario_vehicle, write_dem, write_mcap
    from .virtual_truck.scenario import scenario_from_dict

    head = {"name": "warmup", "vehicle": vehicle_name, "start_latitude_deg": 47.42, "start_longitude_deg": 8.47,
            "start_heading_deg": 70.0, "start_time": dt.datetime(2025, 5, 14, 6, 30, tzinfo=dt.timezone.utc)}
    scenario = scenario_from_dict({"scenario": head, **SHORT_ROUTE}, "<warm-up>", base_dir)
    vehicle = scenario_vehicle(scenario)
    virtual = drive(scenario, vehicle, seed=0, realism=realism_level(realism))
    write_dem(virtual, work_dir / "dem")
    log = write_mcap(virtual, work_dir / "logs" / "warmup.mcap")
    ctx = RunContext(inputs=[log], out_dir=work_dir / "out", vehicle=vehicle, dem_dir=work_dir / "dem",
                     options=WARMUP_OPTIONS, say=lambda _message: None)
    load_inputs(ctx)
    # the results only (writing files and figures compiles nothing), in the demo's order: with
    # the kernels' first-run compilation cut to about a minute, the stages up to the cycle are
    # compiled here before the demo's logging ends, and the simulation's and the design's while
    # the demo searches its cycle
    for stage in STAGES:
        run_stage(ctx, stage)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="compile and cache the analysis kernels (started by analyze demo)")
    parser.add_argument("--vehicle", default="rigid-18t")
    parser.add_argument("--base-dir", type=Path, default=Path("."), help="folder a vehicle file name is relative to")
    parser.add_argument("--realism", default="typical")
    args = parser.parse_args(argv)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(1))  # stopped by the demo: remove the work folder
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGTERM})  # until the folder is under the finally
    work_dir = Path(tempfile.mkdtemp(prefix="haulprofile-warmup-"))
    try:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGTERM})
        warm(args.vehicle, args.realism, work_dir, args.base_dir)
        stamp = stamp_path()
        stamp.parent.mkdir(parents=True, exist_ok=True)
        stamp.touch()
    except Exception:  # noqa: BLE001 - a failed warm-up costs nothing; the run compiles what it needs
        return 1
    finally:
        shutil.rmtree(work_dir, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
