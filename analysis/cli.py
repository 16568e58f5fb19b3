"""The ``analyze`` command: one table of subcommands, each a module with ``add_arguments`` and
``run``. Modules are imported only when their command runs, so ``--help`` stays fast; a command
whose module is not in this installation is not listed."""

from __future__ import annotations

import argparse
import errno
import importlib
import importlib.util
import sys

from .errors import UserError

COMMANDS: dict[str, tuple[str, str]] = {
    "demo": ("haulprofile.analysis.commands.demo", "drive the virtual truck through logger and analysis into demo-out/"),
    "run": ("haulprofile.analysis.commands.run", "run every analysis stage on logs or a signals table"),
    "info": ("haulprofile.analysis.commands.info", "topics, duration, rates, gaps and coverage of logs"),
    "signals": ("haulprofile.analysis.commands.signals", "decode and align logs into a signals table"),
    "recover": ("haulprofile.analysis.commands.recover", "write a repaired, indexed copy of a cut MCAP log"),
    "redact": ("haulprofile.analysis.commands.redact", "copies of logs without positions, NMEA and GPS times in zones"),
    "export": ("haulprofile.analysis.commands.export", "copies of logs as MF4, BLF, ASC, candump or Foxglove MCAP"),
    "vehicle": ("haulprofile.analysis.commands.vehicle", "a VECTO job or vehicle file as a vehicle file (TOML)"),
    "gradient": ("haulprofile.analysis.commands.gradient", "road height and gradient (DEM, barometer, IMU, fused)"),
    "mass": ("haulprofile.analysis.commands.mass", "vehicle mass per segment (LS, RLS, Levenberg-Marquardt)"),
    "cycle": ("haulprofile.analysis.commands.cycle", "representative driving cycle (Markov chain, Monte Carlo)"),
    "loads": ("haulprofile.analysis.commands.loads", "load collectives at the wheel"),
    "simulate": ("haulprofile.analysis.commands.simulate", "longitudinal simulation of the electric truck on a cycle"),
    "design": ("haulprofile.analysis.commands.design", "application requirements and e-powertrain concepts (NSGA-II)"),
    "fleet": ("haulprofile.analysis.commands.fleet", "many logs: map per log, reduce, cycles per vehicle group"),
}


HIDDEN_ALIASES = frozenset({"--output", "--rate", "--duration"})
"""Old spellings still accepted (``--rate`` for ``--rate-hz``, ``--output`` for ``--out``, ``--duration``
for ``--cycle-duration``) but not shown in ``--help``."""
ENVIRONMENT_ERRNOS = {errno.EACCES, errno.EPERM, errno.EROFS, errno.ENOSPC, errno.EDQUOT, errno.ENOTDIR,
                      errno.EISDIR, errno.EEXIST, errno.ENAMETOOLONG}
"""File-system refusals (read-only, full, a file where a directory should be): the user's to fix, exit 2."""


class _HelpFormatter(argparse.HelpFormatter):
    """Help that lists each option under its current names only."""

    def _format_action_invocation(self, action):
        shown = [s for s in action.option_strings if s not in HIDDEN_ALIASES]
        if not action.option_strings or shown == action.option_strings:
            return super()._format_action_invocation(action)
        hidden = action.option_strings
        action.option_strings = shown
        try:
            return super()._format_action_invocation(action)
        finally:
            action.option_strings = hidden


def version() -> str:
    from importlib.metadata import PackageNotFoundError, version as package_version

    try:
        return package_version("haulprofile")
    except PackageNotFoundError:
        return "unknown"


def available_commands() -> dict[str, tuple[str, str]]:
    return {name: spec for name, spec in COMMANDS.items() if importlib.util.find_spec(spec[0]) is not None}


def build_parser(commands: dict[str, tuple[str, str]]) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="analyze", description="haulprofile analysis: truck logs to load profiles.")
    parser.add_argument("--debug", action="store_true", help="show tracebacks")
    parser.add_argument("--version", action="version", version=f"analyze (haulprofile) {version()}")
    parser.add_argument("--identity", metavar="FILE",
                        help="age identity (or OpenSSH private key) to read .mcap.age logs; also after the command")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (_, help_text) in commands.items():
        sub.add_parser(name, help=help_text, add_help=False)
    return parser


def _take_identity(argv: list[str]) -> tuple[list[str], list[str]]:
    """``--identity FILE`` (any number, anywhere): the age identities for ``.mcap.age`` logs."""
    rest, identities, i = [], [], 0
    while i < len(argv):
        if argv[i] == "--identity" and i + 1 < len(argv):
            identities.append(argv[i + 1])
            i += 2
            continue
        if argv[i].startswith("--identity="):
            identities.append(argv[i].split("=", 1)[1])
        else:
            rest.append(argv[i])
        i += 1
    return rest, identities


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    argv, identities = _take_identity(argv)
    commands = available_commands()
    parser = build_parser(commands)
    known, rest = parser.parse_known_args(argv)
    if known.command is None:
        parser.print_help()
        return 2
    module = importlib.import_module(commands[known.command][0])
    sub = argparse.ArgumentParser(prog=f"analyze {known.command}", description=commands[known.command][1],
                                  formatter_class=_HelpFormatter)
    module.add_arguments(sub)
    args = sub.parse_args(rest)
    args.debug = known.debug
    try:
        from .encrypted import use_identity_files
        use_identity_files(identities)
        return int(module.run(args) or 0)
    except UserError as exc:
        if known.debug:
            raise
        from .commands.arguments import in_flags

        print(f"analyze {known.command}: error: {in_flags(str(exc))}", file=sys.stderr)
        return exc.exit_code
    except OSError as exc:
        if not known.debug and exc.errno in ENVIRONMENT_ERRNOS:
            where = f"{exc.filename}: " if exc.filename else ""
            print(f"analyze {known.command}: error: {where}{exc.strerror or exc}", file=sys.stderr)
            return 2
        return _internal_error(exc, known)
    except KeyboardInterrupt:
        print("analyze: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # a bug, not the user's input: one line, the traceback on --debug
        return _internal_error(exc, known)


def _internal_error(exc: Exception, known) -> int:
    if known.debug:
        raise exc
    print(f"analyze {known.command}: internal error: {type(exc).__name__}: {exc} "
          f"(rerun with 'analyze --debug {known.command} ...' and report it)", file=sys.stderr)
    return 1


if __name__ == "__main__":
    sys.exit(main())
