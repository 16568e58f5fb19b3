"""tools/install-pi.sh: its dry run (never run for real here) and its argument checks."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "tools" / "install-pi.sh"


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", str(SCRIPT), *args], capture_output=True, text=True)


def commands(out: str) -> list[str]:
    return [line[2:] for line in out.splitlines() if line.startswith("+ ")]


def test_script_is_strict_bash():
    text = SCRIPT.read_text()
    assert text.startswith("#!/usr/bin/env bash\n") and "set -euo pipefail" in text
    assert subprocess.run(["bash", "-n", str(SCRIPT)]).returncode == 0


@pytest.mark.skipif(shutil.which("shellcheck") is None, reason="shellcheck not installed")
def test_shellcheck():
    assert subprocess.run(["shellcheck", str(SCRIPT)]).returncode == 0


@pytest.mark.parametrize("bitrate, networkd", [("250000", "250K"), ("500000", "500K")])
def test_dry_run_prints_every_install_step(bitrate, networkd):
    result = run("--dry-run", "--can-serial", "0043A1B2", "--bitrate", bitrate)
    assert result.returncode == 0, result.stderr
    steps = commands(result.stdout)
    text = "\n".join(steps)
    assert "apt-get install -y --no-install-recommends python3-venv python3-dev can-utils i2c-tools rsync" in text
    assert "raspi-config nonint do_i2c 0" in text and "mcp2515" not in text
    assert "useradd --system --user-group --home-dir /var/lib/haulprofile" in text
    assert "usermod -a -G i2c haulprofile" in text and "dialout" not in text
    assert "python3 -m venv /opt/haulprofile/venv" in text
    assert "/opt/haulprofile/venv/bin/pip install --upgrade /opt/haulprofile/src[logger]" in text
    assert "/etc/udev/rules.d/80-haulprofile.rules" in text
    assert f"s/^BitRate=.*/BitRate={networkd}/" in text
    assert f"bitrate = {bitrate}" in text and "/dev/haulprofile-gps" in text
    assert "haulprofile-logger --config /etc/haulprofile/logger.toml --check" in text
    assert steps[-1] == "systemctl restart haulprofile-logger.service"
    assert "systemctl enable --now haulprofile-logger.service" in text
    order = [next(i for i, s in enumerate(steps) if key in s)
             for key in ("apt-get install", "useradd", "pip install --upgrade /opt", "udev/80", "logger.toml",
                         "daemon-reload", "enable --now haulprofile")]
    assert order == sorted(order)


def test_dry_run_with_the_mcp2515_overlay_and_no_start():
    result = run("--dry-run", "--mcp2515", "--no-start")
    assert result.returncode == 0, result.stderr
    text = result.stdout
    assert "dtoverlay=mcp2515-can0,oscillator=16000000,interrupt=25" in text and "do_spi 0" in text
    assert "systemctl enable haulprofile-logger.service" in text and "--now haulprofile" not in text


@pytest.mark.parametrize("args, message", [
    (["--bitrate", "125000"], "--bitrate must be 250000 (J1939) or 500000 (OBD-II), got 125000"),
    (["--bitrate"], "--bitrate needs a value"),
    (["--frobnicate"], "unknown option --frobnicate"),
])
def test_bad_arguments_are_one_line(args, message):
    result = run("--dry-run", "--can-serial", "0043A1B2", *args)
    assert result.returncode == 2 and message in result.stderr and result.stderr.count("\n") == 1
    assert result.stdout == ""


def test_listen_only_unless_transmit_is_asked_for():
    network = (SCRIPT.parents[1] / "udev" / "80-haulprofile-can.network").read_text()
    assert "\nListenOnly=yes\n" in network
    quiet = run("--dry-run", "--can-serial", "0043A1B2").stdout
    assert "ListenOnly=no" not in quiet and "listen_only = false" not in quiet
    loud = run("--dry-run", "--can-serial", "0043A1B2", "--transmit")
    assert loud.returncode == 0, loud.stderr
    assert "s/^ListenOnly=.*/ListenOnly=no/" in loud.stdout
    assert "s|^listen_only = true |listen_only = false|" in loud.stdout and "WARNING: --transmit" in loud.stdout


@pytest.mark.parametrize("args, rule", [
    (["--can-serial", "0043A1B2"], 'KERNEL=="can*", ATTRS{serial}=="0043A1B2", NAME="hpcan0"'),
    (["--can-path", "1-1.3"], 'KERNEL=="can*", KERNELS=="1-1.3", NAME="hpcan0"'),
    (["--mcp2515"], 'KERNEL=="can*", DRIVERS=="mcp251x", KERNELS=="spi0.0", NAME="hpcan0"'),
])
def test_the_logger_s_own_can_adapter_is_named_by_serial_or_port(args, rule):
    result = run("--dry-run", *args)
    assert result.returncode == 0, result.stderr
    written = [l for l in result.stdout.splitlines() if l.startswith("+ write /etc/udev/rules.d/79-haulprofile-can.rules")]
    assert len(written) == 1 and written[0].endswith(rule)
    assert 'channel = \\"hpcan0\\"' in result.stdout or 'channel = "hpcan0"' in result.stdout
    assert "install -m 0640 -g haulprofile" in result.stdout  # the configuration may hold zones


@pytest.mark.parametrize("args, message", [
    ([], "name the logger's CAN adapter: --can-serial SERIAL, --can-path USB-PORT or --mcp2515"),
    (["--can-serial", 'x" RUN+="/bin/sh'], "--can-serial: letters, digits and . _ : - only"),
    (["--can-path", "usb1"], "--can-path: a USB port such as 1-1.3"),
])
def test_can_adapter_arguments_are_checked(args, message):
    result = run("--dry-run", *args)
    assert result.returncode == 2 and message in result.stderr and result.stderr.count("\n") == 1


def test_recipient_turns_encryption_on_and_is_checked():
    key = "age1pquupsq8hn9xj5x3h7fdszz4y9l5sd6wl0gqzh3vxrwgf7e4vydsxsxvnt"
    result = run("--dry-run", "--can-serial", "0043A1B2", "--recipient", key)
    assert result.returncode == 0 and f'recipients = ["{key}"]' in result.stdout
    bad = run("--dry-run", "--can-serial", "0043A1B2", "--recipient", "AGE-SECRET-KEY-1QQQ")
    assert bad.returncode == 2 and "--recipient must be an age public key" in bad.stderr
