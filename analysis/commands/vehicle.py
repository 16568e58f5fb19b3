"""``analyze vehicle FILE [-o truck.toml]``: a VECTO job or vehicle file as our vehicle file (TOML),
or a vehicle file checked; printed, or written to a new file."""

from __future__ import annotations

import sys
from pathlib import Path

from ..errors import UserError


def add_arguments(parser) -> None:
    parser.add_argument("vehicle", help="a VECTO job (.vecto) or vehicle (.vveh) file, or a vehicle file (TOML) "
                                        "or shipped example name to check")
    parser.add_argument("-o", "--out", "--output", dest="out", type=Path,
                        help="vehicle file (TOML) to write (never over an existing file); default: print it")


def run(args) -> int:
    from ..vecto_vehicle import SUFFIXES, vehicle_toml
    from ..vehicle import load_vehicle

    vehicle = load_vehicle(args.vehicle)
    if Path(args.vehicle).suffix.lower() not in SUFFIXES:
        print(f"{args.vehicle}: a valid vehicle file ({vehicle.name})", file=sys.stderr)
        return 0
    text = vehicle_toml(args.vehicle)
    if args.out is None:
        sys.stdout.write(text)
        return 0
    if args.out.exists():
        raise UserError(f"{args.out} exists; choose a new file name for the vehicle file")
    from haulprofile.contract.private_files import open_new

    with open_new(args.out) as stream:
        stream.write(text.encode("utf-8"))
    print(f"wrote {args.out}", file=sys.stderr)
    return 0
