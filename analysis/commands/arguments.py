"""What the commands share: the arguments several of them take, their defaults read from the
stages' options, the parsers of command-line strings, and the one table that says which flag sets
which option field, so an error of the domain code (which names fields) reads in flags here."""

from __future__ import annotations

import re
from pathlib import Path

from ..errors import UserError
from ..plausible import known_mass_kg

FLAGS = {
    "dem_dir": "--dem",
    "vehicle_file": "--vehicle",
    "ingest.rate_hz": "--rate-hz",
    "ingest.dbc": "--dbc",
    "mass.known_mass_kg": "--mass-kg",
    "known_mass_kg": "--mass-kg",
    "gradient.flat_road": "--flat-road",
    "flat_road": "--flat-road",
    "mass.weighed_masses_kg": "--known-mass",
    "known_masses": "--known-mass",
    "mass.true_mass_kg": "--true-mass",
    "cycle.duration_s": "--cycle-duration",
    "cycle.n_candidates": "--candidates",
    "cycle.n_cycles": "--cycles",
    "cycle.seed": "--seed",
    "simulation.payload_kg": "--payload-kg",
    "simulation.cycle_file": "CYCLE",
    "loads.generated_file": "--cycle",
    "output.private": "--private",
    "fleet.workers": "--workers",
}
"""Option field (``stage.field`` for a stage's options) → the flag that sets it."""

_FIELD = re.compile("|".join(rf"(?<![\w.-]){re.escape(name)}(?![\w])" for name in sorted(FLAGS, key=len, reverse=True)))


def in_flags(message: str) -> str:
    """A domain message with the option fields it names replaced by their flags."""
    return _FIELD.sub(lambda match: FLAGS[match.group(0)], message)


def printer(quiet: bool = False, stream=None):
    """A ``say`` for the stages: their messages in flags, on ``stream`` (stdout), or nothing."""
    if quiet:
        return lambda _message: None
    return lambda message: print(in_flags(message), file=stream)


def add_inputs(parser, what: str = "MCAP logs, directories of logs, or signals tables") -> None:
    parser.add_argument("inputs", nargs="+", type=Path, help=what)


def add_vehicle(parser, required: bool = True, what: str = "") -> None:
    parser.add_argument("--vehicle", required=required,
                        help="vehicle file (TOML) or a shipped example name" + (f", {what}" if what else ""))


def add_dem(parser, what: str = "") -> None:
    parser.add_argument("--dem", type=Path, help="directory of SRTM .hgt tiles or GeoTIFFs" + (f" ({what})" if what else ""))


def add_out(parser, default: Path | None = None, what: str = "output directory") -> None:
    """``-o/--out`` (``--output`` still accepted): required where there is no default."""
    parser.add_argument("-o", "--out", "--output", dest="out", type=Path, default=default, required=default is None,
                        help=what + (f" (default {default})" if default is not None else ""))


def add_rate(parser) -> None:
    from ..ingest.stage import IngestOptions

    default = IngestOptions.rate_hz
    parser.add_argument("--rate-hz", "--rate", dest="rate_hz", type=float, default=default,
                        help=f"rate of the signals table [Hz] ({default:g})")


def add_cycle(parser) -> None:
    """The cycle stage's length, candidates and seed, with the stage's own defaults."""
    from ..markov.stage import CycleOptions

    defaults = CycleOptions()
    parser.add_argument("--cycle-duration", "--duration", dest="cycle_duration", type=float,
                        default=defaults.duration_s, help=f"generated cycle length [s] ({defaults.duration_s:g})")
    parser.add_argument("--candidates", type=int, default=defaults.n_candidates,
                        help="Monte Carlo candidates (default: the refined selection's pool of 20000, or "
                             "100000 for the paper's selection)")
    parser.add_argument("--seed", type=int, default=defaults.seed,
                        help=f"random seed of the cycle generation ({defaults.seed})")


def add_design_search(parser) -> None:
    """The design stage's search size: NSGA-II population and generations, its defaults."""
    from ..design.options import DesignOptions

    defaults = DesignOptions()
    parser.add_argument("--design-population", type=int, default=defaults.population,
                        help=f"NSGA-II population of the e-powertrain concept search ({defaults.population})")
    parser.add_argument("--design-generations", type=int, default=defaults.generations,
                        help=f"NSGA-II generations of the concept search ({defaults.generations}; population x "
                             f"generations candidates are simulated)")
    add_ownership(parser)


def add_ownership(parser) -> None:
    """The cost-of-ownership figures the design stage chooses its concept by, its defaults."""
    from ..design.options import DesignOptions

    defaults = DesignOptions()
    parser.add_argument("--energy-price-eur-per-kwh", type=float, default=defaults.energy_price_eur_per_kwh,
                        help=f"price of a kWh at the battery, charging losses included, in the concept's cost of "
                             f"ownership ({defaults.energy_price_eur_per_kwh:g})")
    parser.add_argument("--service-life-years", type=float, default=defaults.service_life_years,
                        help=f"years the energy is paid over in the cost of ownership ({defaults.service_life_years:g})")
    parser.add_argument("--operating-days", type=float, default=defaults.operating_days_per_year,
                        help=f"working days a year, each driving the daily distance ({defaults.operating_days_per_year:g})")


def design_options(args):
    """`DesignOptions` of the design arguments (`add_design_search`); UserError, one line, for a
    search too small or a cost-of-ownership figure out of range."""
    from ..design.options import DesignOptions
    from ..design.synthesis import check_options

    if args.design_population < 4 or args.design_generations < 1:
        raise UserError(f"--design-population must be at least 4 and --design-generations at least 1, got "
                        f"{args.design_population} and {args.design_generations}")
    options = DesignOptions(population=args.design_population, generations=args.design_generations,
                            energy_price_eur_per_kwh=args.energy_price_eur_per_kwh,
                            service_life_years=args.service_life_years,
                            operating_days_per_year=args.operating_days)
    check_options(options)
    return options


def parse_known_masses(items: list[str] | None) -> dict[int, float]:
    """``["SEGMENT=KG", ...]`` (segment numbers from 1, as printed) -> {index from 0: kg}; a bare
    ``KG`` means the first segment. UserError on anything else."""
    known = {}
    for item in items or []:
        segment, _, kg = item.rpartition("=")
        try:
            index = int(segment) - 1 if segment else 0
            mass = float(kg)
        except ValueError:
            raise UserError(f"--known-mass {item!r}: expected SEGMENT=KG (e.g. 2=18400) or KG") from None
        if index < 0 or not mass > 0:
            raise UserError(f"--known-mass {item!r}: segment numbers start at 1 and the mass must be positive")
        known[index] = known_mass_kg(mass, f"--known-mass {item!r}")
    return known


def parse_fleet_known_masses(items: list[str] | None) -> list[tuple[str, str, int, float]]:
    """``["TRUCK:LOG:SEGMENT=KG", ...]`` → (truck, log, segment number from 1, kg); ``LOG`` is the
    log's path under its directory, its file name or its stem. UserError on anything else."""
    out = []
    for item in items or []:
        where, _, kg = item.rpartition("=")
        parts = where.split(":")
        try:
            truck, log, segment = parts if len(parts) == 3 else ([] if len(parts) != 2 else [*parts, "1"])
            number, mass = int(segment), float(kg)
        except ValueError:
            raise UserError(f"--known-mass {item!r}: expected TRUCK:LOG:SEGMENT=KG (e.g. rigid:drive-00.mcap:2=18400)"
                            ) from None
        if not truck or not log or number < 1 or not mass > 0:
            raise UserError(f"--known-mass {item!r}: give the truck (log directory), the log, a segment number "
                            f"from 1 and a positive mass in kg")
        out.append((truck, log, number, known_mass_kg(mass, f"--known-mass {item!r}")))
    return out


def add_known_road_and_mass(parser) -> None:
    """``--mass-kg`` and ``--flat-road``: what a log without the sensors for an estimate (a CAN-only
    recording) needs to reach loads and a cycle."""
    parser.add_argument("--mass-kg", type=float,
                        help="a known total mass [kg] for the whole drive instead of estimating one")
    parser.add_argument("--flat-road", action="store_true",
                        help="take the road as flat (gradient 0 %%) instead of estimating it; said so in the "
                             "summary and the report")


def check_mass_kg(mass_kg: float | None) -> None:
    if mass_kg is not None and not mass_kg > 0:
        raise UserError(f"--mass-kg must be a positive mass in kg, got {mass_kg}")


def refuse_cycles(inputs, command: str) -> None:
    """A VECTO cycle is a drive for ``run``, ``info``, ``cycle`` and ``simulate`` and a cycle to
    compare for ``loads --cycle``; the estimating commands have nothing to estimate in it."""
    from ..signals import CYCLE_SUFFIXES

    for path in inputs:
        if Path(path).suffix.lower() in CYCLE_SUFFIXES:
            raise UserError(f"{path}: a VECTO cycle already holds its gradient and no sensor data, so 'analyze "
                            f"{command}' has nothing to estimate in it; use it with 'analyze run', 'info', 'simulate' "
                            f"or 'loads --cycle'")
