#!/usr/bin/env bash
# Install the haulprofile logger on Raspberry Pi OS (Bookworm, 64-bit): packages, I2C, the
# service user, a venv under /opt/haulprofile, udev rules, the can0 networkd file, the
# configuration and the systemd unit. Idempotent: run it again after `git pull` to update.
# See docs/raspberry-pi.md.
#
#   sudo tools/install-pi.sh (--can-serial SERIAL | --can-path USB-PORT | --mcp2515)
#                            [--bitrate 250000|500000] [--recipient AGE-PUBLIC-KEY] [--transmit]
#                            [--no-start] [--dry-run]
#
#   --can-serial  the logger's USB CAN adapter by its serial number (udevadm info -a
#                 /sys/class/net/can0 | grep serial); it becomes hpcan0, other adapters keep can1...
#   --can-path    ... or by the USB port it is plugged into (e.g. 1-1.3)
#   --recipient   the fleet's age public key (age1...): closed logs are encrypted to it and the
#                 plaintext removed (docs/privacy.md); the Pi never holds the identity
#   (default) listen-only: the CAN controller (networkd ListenOnly=yes) and the daemon
#               (can.listen_only = true) put nothing on the truck's bus
#   --transmit  let the logger send OBD-II requests and J1939 requests (ListenOnly=no,
#               can.listen_only = false); only with the fleet's agreement for that truck
#   --bitrate   CAN bitrate of can0: 250000 (J1939/FMS, heavy trucks; default) or 500000 (OBD-II)
#   --mcp2515   the MCP2515 SPI CAN HAT on spi0.0 is the logger's adapter: enable its overlay
#               (16 MHz crystal, interrupt on GPIO 25); a reboot is needed afterwards
#   --no-start  install and enable, but do not start the service now
#   --dry-run   print every command instead of running it (needs neither root nor a Pi)
set -euo pipefail

BITRATE=250000
MCP2515=0
START=1
DRY_RUN=0
TRANSMIT=0
CAN_SERIAL=""
CAN_PATH=""
CAN_NAME=hpcan0
RECIPIENT=""
PREFIX=/opt/haulprofile
CONFIG_DIR=/etc/haulprofile
SERVICE_USER=haulprofile
SOURCE="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BOOT_CONFIG=/boot/firmware/config.txt
[[ -f $BOOT_CONFIG || ! -f /boot/config.txt ]] || BOOT_CONFIG=/boot/config.txt  # before Bookworm

die() { echo "install-pi.sh: error: $*" >&2; exit 2; }

while [[ $# -gt 0 ]]; do
    case "$1" in
        --bitrate) [[ $# -ge 2 ]] || die "--bitrate needs a value (250000 or 500000)"; BITRATE="$2"; shift 2 ;;
        --bitrate=*) BITRATE="${1#*=}"; shift ;;
        --mcp2515) MCP2515=1; shift ;;
        --transmit) TRANSMIT=1; shift ;;
        --recipient) [[ $# -ge 2 ]] || die "--recipient needs the fleet's age public key (age1...)"; RECIPIENT="$2"; shift 2 ;;
        --can-serial) [[ $# -ge 2 ]] || die "--can-serial needs the adapter's serial number"; CAN_SERIAL="$2"; shift 2 ;;
        --can-path) [[ $# -ge 2 ]] || die "--can-path needs the USB port (e.g. 1-1.3)"; CAN_PATH="$2"; shift 2 ;;
        --no-start) START=0; shift ;;
        --dry-run) DRY_RUN=1; shift ;;
        -h|--help) sed -n '2,27p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
        *) die "unknown option $1 (see --help)" ;;
    esac
done
case "$BITRATE" in
    250000) NETWORKD_BITRATE=250K ;;
    500000) NETWORKD_BITRATE=500K ;;
    *) die "--bitrate must be 250000 (J1939) or 500000 (OBD-II), got $BITRATE" ;;
esac
if [[ -n $RECIPIENT && ! $RECIPIENT =~ ^age1[02-9ac-hj-np-z]{58}$ ]]; then
    die "--recipient must be an age public key (age1 and 58 more characters), got $RECIPIENT"
fi
if [[ -n $CAN_SERIAL ]]; then
    [[ $CAN_SERIAL =~ ^[A-Za-z0-9._:-]+$ ]] || die "--can-serial: letters, digits and . _ : - only, got $CAN_SERIAL"
    CAN_RULE="SUBSYSTEM==\"net\", ACTION==\"add\", KERNEL==\"can*\", ATTRS{serial}==\"$CAN_SERIAL\", NAME=\"$CAN_NAME\""
elif [[ -n $CAN_PATH ]]; then
    [[ $CAN_PATH =~ ^[0-9]+-[0-9.]+$ ]] || die "--can-path: a USB port such as 1-1.3, got $CAN_PATH"
    CAN_RULE="SUBSYSTEM==\"net\", ACTION==\"add\", KERNEL==\"can*\", KERNELS==\"$CAN_PATH\", NAME=\"$CAN_NAME\""
elif [[ $MCP2515 -eq 1 ]]; then
    CAN_RULE="SUBSYSTEM==\"net\", ACTION==\"add\", KERNEL==\"can*\", DRIVERS==\"mcp251x\", KERNELS==\"spi0.0\", NAME=\"$CAN_NAME\""
else
    die "name the logger's CAN adapter: --can-serial SERIAL, --can-path USB-PORT or --mcp2515"
fi
[[ -f "$SOURCE/pyproject.toml" && -f "$SOURCE/systemd/haulprofile-logger.service" ]] \
    || die "$SOURCE is not a haulprofile checkout"
if [[ $DRY_RUN -eq 0 && $EUID -ne 0 ]]; then
    die "run as root (sudo), or with --dry-run to see what it would do"
fi

run() {  # a command, printed; executed unless --dry-run
    echo "+ $*"
    if [[ $DRY_RUN -eq 0 ]]; then "$@"; fi
}

append_once() {  # LINE FILE: add a line to a file unless it is there
    if [[ $DRY_RUN -eq 1 ]]; then
        echo "+ grep -qxF '$1' $2 || echo '$1' >> $2"
    elif ! grep -qxF "$1" "$2"; then
        echo "+ echo '$1' >> $2"
        echo "$1" >> "$2"
    fi
}

echo "== packages"
run apt-get update
run apt-get install -y --no-install-recommends python3-venv python3-dev can-utils i2c-tools rsync

echo "== I2C (and the MCP2515 CAN HAT)"
run raspi-config nonint do_i2c 0
if [[ $MCP2515 -eq 1 ]]; then
    run raspi-config nonint do_spi 0
    append_once "dtoverlay=mcp2515-can0,oscillator=16000000,interrupt=25" "$BOOT_CONFIG"
    echo "   (reboot once for the MCP2515 overlay)"
fi

echo "== service user $SERVICE_USER (group i2c; the GPS tty is given to its own group by udev)"
if [[ $DRY_RUN -eq 1 ]] || ! getent group i2c > /dev/null; then
    run groupadd --system -f i2c
fi
if [[ $DRY_RUN -eq 1 ]] || ! id -u "$SERVICE_USER" > /dev/null 2>&1; then
    run useradd --system --user-group --home-dir /var/lib/haulprofile --no-create-home \
        --shell /usr/sbin/nologin "$SERVICE_USER"
fi
run usermod -a -G i2c "$SERVICE_USER"

echo "== code and venv in $PREFIX"
run install -d -m 0755 "$PREFIX" "$PREFIX/src" "$PREFIX/docs"
run rsync -a --delete --exclude .git --exclude .bench-cache --exclude '__pycache__' "$SOURCE/" "$PREFIX/src/"
run rsync -a "$SOURCE/docs/" "$PREFIX/docs/"
if [[ $DRY_RUN -eq 1 || ! -x "$PREFIX/venv/bin/python" ]]; then
    run python3 -m venv "$PREFIX/venv"
fi
run "$PREFIX/venv/bin/pip" install --upgrade pip
run "$PREFIX/venv/bin/pip" install --upgrade "$PREFIX/src[logger]"

echo "== udev rules and $CAN_NAME at $BITRATE bit/s (systemd-networkd)"
run install -m 0644 "$SOURCE/udev/80-haulprofile.rules" /etc/udev/rules.d/80-haulprofile.rules
echo "+ write /etc/udev/rules.d/79-haulprofile-can.rules: $CAN_RULE"
if [[ $DRY_RUN -eq 0 ]]; then
    printf '# written by tools/install-pi.sh: the logger'"'"'s CAN adapter\n%s\n' "$CAN_RULE" \
        > /etc/udev/rules.d/79-haulprofile-can.rules
fi
run install -d -m 0755 /etc/systemd/network
run install -m 0644 "$SOURCE/udev/80-haulprofile-can.network" /etc/systemd/network/80-haulprofile-can.network
run sed -i "s/^BitRate=.*/BitRate=$NETWORKD_BITRATE/" /etc/systemd/network/80-haulprofile-can.network
if [[ $TRANSMIT -eq 1 ]]; then
    run sed -i "s/^ListenOnly=.*/ListenOnly=no/" /etc/systemd/network/80-haulprofile-can.network
fi
run udevadm control --reload
run udevadm trigger --subsystem-match=net --subsystem-match=tty --subsystem-match=i2c-dev
run systemctl enable --now systemd-networkd
run networkctl reload

echo "== configuration $CONFIG_DIR/logger.toml"
run install -d -m 0750 -g "$SERVICE_USER" "$CONFIG_DIR"
if [[ $DRY_RUN -eq 1 || ! -f "$CONFIG_DIR/logger.toml" ]]; then
    run install -m 0640 -g "$SERVICE_USER" "$SOURCE/logger/logger.example.toml" "$CONFIG_DIR/logger.toml"
    run sed -i -e "s|^bitrate = [0-9]*|bitrate = $BITRATE|" \
        -e "s|^channel = \"can0\"|channel = \"$CAN_NAME\"|" \
        -e 's|^port = "/dev/ttyACM0"|port = "/dev/haulprofile-gps"|' "$CONFIG_DIR/logger.toml"
    if [[ -n $RECIPIENT ]]; then
        run sed -i "s|^recipients = \[\]|recipients = [\"$RECIPIENT\"]|" "$CONFIG_DIR/logger.toml"
    fi
    if [[ $TRANSMIT -eq 1 ]]; then
        echo "   WARNING: --transmit: the logger will send OBD-II and J1939 requests on the truck's CAN bus"
        run sed -i "s|^listen_only = true |listen_only = false|" "$CONFIG_DIR/logger.toml"
    fi
else
    echo "   $CONFIG_DIR/logger.toml exists: left as it is (set can.bitrate = $BITRATE there if it changed)"
fi
run "$PREFIX/venv/bin/haulprofile-logger" --config "$CONFIG_DIR/logger.toml" --check

echo "== systemd unit"
run install -m 0644 "$SOURCE/systemd/haulprofile-logger.service" /etc/systemd/system/haulprofile-logger.service
run systemctl daemon-reload
if [[ $START -eq 1 ]]; then
    run systemctl enable --now haulprofile-logger.service
    run systemctl restart haulprofile-logger.service
else
    run systemctl enable haulprofile-logger.service
fi

echo "== done: check with  systemctl status haulprofile-logger  and"
echo "   sudo -u $SERVICE_USER $PREFIX/venv/bin/haulprofile-logger --config $CONFIG_DIR/logger.toml --status"
