"""``analyze demo [--out DIR] [--scenario NAME] [--seed N]``: the whole product on a virtual truck.

Drives a scenario (regional route with a tunnel by default) at a realism level (``typical`` by
default: terrain with an engineered road, a DEM with real DEMs' errors, sensors with real errors),
writes its DEM as SRTM tiles into ``DIR/dem/`` and its ground truth into ``DIR/truth*`` (10 Hz
states, the road per 10 m, the mass per segment and every injected error), logs its sensor streams through the
real logger daemon against the device emulators (ECU on a virtual CAN bus, register-level I2C
sensors, NMEA GPS on a pty) into ``DIR/logs/``, then runs every analysis stage on the log into
``DIR``. The emulated world runs ``--time-scale`` times faster than real time (40: the 38-minute
drive is logged in under a minute, a progress line every 10 s); ``--direct`` writes the log without
the daemon, in seconds. While the demo drives and the daemon logs, `warmup` compiles the analysis
kernels in a second process, so a first run does not wait for numba after the logging.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path

from haulprofile.contract.private_files import make_dirs
from haulprofile.logger.emulators.compression import DEMO_TIME_SCALE

from .. import warmup
from ..manifest import Manifest, staged_files
from ..pipeline import Options, RunContext, run as run_pipeline
from ..virtual_truck import drive, load_scenario, realism_level, scenario_vehicle, write_dem, write_mcap, write_truth
from .arguments import add_design_search, design_options, printer


def add_arguments(parser) -> None:
    parser.add_argument("-o", "--out", "--output", dest="out", type=Path, default=Path("demo-out"),
                        help="output directory (default demo-out)")
    parser.add_argument("--scenario", default="regional-tunnel",
                        help="shipped scenario name (urban-delivery, regional-tunnel, long-haul) or a TOML file")
    parser.add_argument("--seed", type=int, default=0, help="seed of the virtual world and its sensor noise")
    parser.add_argument("--realism", default="typical",
                        help="ideal (the old, exact world), typical (default) or harsh")
    parser.add_argument("--time-scale", type=float, default=DEMO_TIME_SCALE,
                        help=f"emulated seconds per real second while logging through the daemon ({DEMO_TIME_SCALE:g})")
    parser.add_argument("--direct", action="store_true",
                        help="write the log directly (analysis.virtual_truck.write_mcap), not through the daemon")
    parser.add_argument("--no-warmup", action="store_true",
                        help="do not compile the analysis kernels in a second process while logging (they are "
                             "compiled where first used instead)")
    add_design_search(parser)
    parser.add_argument("--quiet", action="store_true", help="print only errors and where to look")


def progress_line(progress) -> str:
    """``  logging: 3.2 of 38.3 min driven, 48 000 CAN frames`` from a rig `Progress`."""
    frames = f"{progress.can_frames:,}".replace(",", " ")
    return (f"  logging: {progress.driven_s / 60:.1f} of {progress.duration_s / 60:.1f} min driven, "
            f"{frames} CAN frames")


def run(args) -> int:
    say = printer(args.quiet)
    started = time.perf_counter()
    options = Options(design=design_options(args))
    scenario = load_scenario(args.scenario)
    level = realism_level(args.realism)
    vehicle = scenario_vehicle(scenario)
    say(f"virtual truck: scenario {scenario.name}, {vehicle.name}, seed {args.seed}, realism {level.level}")
    with warmup.beside(not (args.direct or args.no_warmup), scenario, level.level):
        virtual = drive(scenario, vehicle, seed=args.seed, realism=level)
        say(f"  drove {virtual.truth['distance_m'].iloc[-1] / 1000:.1f} km in {virtual.duration_s / 60:.1f} min")
        return _log_and_analyse(args, say, started, options, scenario, vehicle, virtual)


def _log_and_analyse(args, say, started, options, scenario, vehicle, virtual) -> int:
    out: Path = args.out
    manifest = Manifest(out)
    make_dirs(out)
    staging = Path(tempfile.mkdtemp(prefix=".partial-demo-", dir=out))
    try:
        tiles = write_dem(virtual, staging / "dem")
        say(f"  DEM: {', '.join(p.name for p in tiles)} in {out / 'dem'}")
        if args.direct:
            log = write_mcap(virtual, staging / "logs" / f"{scenario.name}-seed{args.seed}.mcap")
        else:
            from haulprofile.logger.emulators import record_streams

            say(f"  logging through the daemon and the emulated devices at {args.time_scale:g}x real time "
                f"(about {virtual.duration_s / args.time_scale:.0f} s)")
            log = record_streams(virtual.sensors, staging / "logs", time_scale=args.time_scale,
                                 progress=lambda p: say(progress_line(p)))
        truth = write_truth(virtual, staging)
        for earlier in manifest.under("logs"):  # the demo's own earlier logs; a user's stay
            manifest.remove(earlier)
        manifest.place(staging, staged_files(staging))
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    log = out / log.relative_to(staging)
    say(f"  log: {log} ({log.stat().st_size / 1e6:.1f} MB)")
    say(f"  ground truth: {', '.join(p.name for p in truth)} in {out}")

    ctx = RunContext(inputs=[log], out_dir=out, vehicle=vehicle, dem_dir=out / "dem", options=options, say=say)
    run_pipeline(ctx)
    elapsed = time.perf_counter() - started
    print(f"demo done in {elapsed:.0f} s. Look at:")
    for name in ("report.html", "summary.json", "signals.parquet"):
        if (out / name).exists():
            print(f"  {out / name}")
    print(f"  {out / 'truth.parquet'}, truth-road-10m.csv, truth-mass.csv, truth-errors.json  (the virtual "
          f"truck's ground truth and every injected error, to compare with the estimates)")
    return 0
