"""The systemd unit's hardening and the udev/networkd files' contents."""

import configparser
import re
import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
UNIT = REPO / "systemd" / "haulprofile-logger.service"


def unit_values(key: str) -> list[str]:
    return [m.group(1).strip() for m in re.finditer(rf"^{key}=(.*)$", UNIT.read_text(), re.M)]


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="systemd-analyze not installed (Debian package systemd)")
def test_security_score_at_most_1_5():
    out = subprocess.run(["systemd-analyze", "security", "--offline=yes", str(UNIT)],
                         capture_output=True, text=True, check=True).stdout
    score = float(re.search(r"Overall exposure level for \S+: ([0-9.]+)", out).group(1))
    print(f"systemd-analyze security exposure: {score}")
    assert score <= 1.5


def test_unit_is_notify_with_watchdog_and_own_user():
    assert unit_values("Type") == ["notify"]
    assert int(unit_values("WatchdogSec")[0]) > 0
    assert unit_values("Restart") == ["always"]
    assert unit_values("User") == ["haulprofile"]
    assert set(unit_values("SupplementaryGroups")[0].split()) == {"i2c"}  # no dialout: not every serial port
    assert unit_values("ProtectSystem") == ["strict"]
    assert unit_values("StateDirectory") == ["haulprofile"]
    assert set(unit_values("RestrictAddressFamilies")[0].split()) == {"AF_CAN", "AF_UNIX", "AF_NETLINK"}
    assert unit_values("DevicePolicy") == ["closed"]
    assert unit_values("DeviceAllow") == ["/dev/i2c-1 rw", "/dev/haulprofile-gps rw"]  # no char-ttyACM/ttyUSB


def test_can_network_file_sets_j1939_bitrate():
    parser = configparser.ConfigParser()
    parser.read(REPO / "udev" / "80-haulprofile-can.network")
    assert parser["Match"]["Name"] == "hpcan0"
    assert parser["CAN"]["BitRate"] == "250K"
    assert parser["CAN"]["ListenOnly"] == "yes"


def test_udev_rules_are_well_formed():
    keys = re.compile(r'^(SUBSYSTEM|ACTION|ATTRS\{\w+\}|DRIVERS|KERNELS?|NAME|SYMLINK|GROUP|MODE)(==|=|\+=)"[^"]*"$')
    lines = [l for l in (REPO / "udev" / "80-haulprofile.rules").read_text().splitlines()
             if l.strip() and not l.startswith("#")]
    assert lines
    for line in lines:
        for part in line.split(", "):
            assert keys.match(part), f"bad udev key in: {line}"
    text = "\n".join(lines)
    assert "NAME=" not in text  # no adapter is renamed by vendor id: install-pi.sh writes the one by serial/port
    assert 'SYMLINK+="haulprofile-gps", GROUP="haulprofile", MODE="0660"' in text and "dialout" not in text
    templates = [l[1:].strip() for l in (REPO / "udev" / "80-haulprofile.rules").read_text().splitlines()
                 if l.startswith("#   SUBSYSTEM")]
    assert len(templates) == 3
    for line in templates:
        for part in line.split(", "):
            assert keys.match(part.replace("<", "").replace(">", "")), f"bad udev key in: {line}"
