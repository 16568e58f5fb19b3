"""``haulprofile-logger --config FILE``: run the daemon (or ``--check`` the file, or print the
running logger's ``--status``, and exit)."""

from __future__ import annotations

import argparse
import asyncio
import logging
import sys

from . import config as config_module
from . import preflight


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="haulprofile-logger",
                                     description="In-truck logger: CAN, I2C sensors and GPS into crash-safe MCAP.")
    parser.add_argument("--version", action="version", version=f"haulprofile-logger (haulprofile) {_version()}")
    parser.add_argument("--config", required=True, help="TOML configuration file (see docs/logger.md)")
    parser.add_argument("--check", action="store_true",
                        help="read and check the configuration and that the log directory is writable")
    parser.add_argument("--duration", type=float, default=None,
                        help="stop after this many (emulated) seconds; default: until SIGTERM")
    parser.add_argument("--status", action="store_true",
                        help="print the health of the running logger (its newest file's /diagnostics) and exit; "
                             "exit code 1 if a source is not running or the file is stale")
    parser.add_argument("-v", "--verbose", action="store_true")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="haulprofile-logger: %(message)s")
    try:
        config = config_module.load(args.config)
    except config_module.ConfigError as exc:
        print(f"haulprofile-logger: error: {exc}", file=sys.stderr)
        return 2
    if args.status:
        from .status import status_lines
        lines, healthy = status_lines(config.logger.directory, config.logger.prefix, enabled_sources(config))
        print("\n".join(lines))
        return 0 if healthy else 1
    try:
        preflight.check(config)
    except config_module.ConfigError as exc:
        print(f"haulprofile-logger: error: {exc}", file=sys.stderr)
        return 2
    if args.check:
        print(f"haulprofile-logger: {args.config} is valid and {config.logger.directory} is writable")
        return 0
    return asyncio.run(_run(config, args.duration))


def enabled_sources(config) -> list[str]:
    """Names of the sources the configuration asks for (as in ``/diagnostics``)."""
    return [name for name in ("can", "i2c", "gps") if getattr(config, name).enabled]


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("haulprofile")
    except PackageNotFoundError:
        return "unknown"


async def _run(config, duration_s: float | None) -> int:
    from .clock import Clock
    from .daemon import Daemon
    clock = Clock(config.logger.time_scale)
    if config.emulation.enabled:
        from .emulators.rig import EmulatedDevices, load_signals, run_daemon_for
        devices = EmulatedDevices(load_signals(config.emulation.signals), clock).start(config)
        daemon = Daemon(config, devices, clock)
        return await run_daemon_for(daemon, devices, duration_s if duration_s is not None else float("inf"))
    daemon = Daemon(config, clock=clock)
    if duration_s is None:
        return await daemon.run()
    task = asyncio.create_task(daemon.run())
    await asyncio.sleep(duration_s)
    daemon.stop()
    return await task


if __name__ == "__main__":
    sys.exit(main())
