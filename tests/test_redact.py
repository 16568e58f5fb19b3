"""``analyze redact``: a log recorded without zones, redacted afterwards. The copy is a complete,
indexed MCAP; nothing of what was inside a zone survives anywhere in it (chunks decompressed,
summary, metadata and chunk indexes included); every other topic is byte-exact; the input is
untouched and cannot be overwritten."""

from __future__ import annotations

import hashlib
import json
import struct

import pytest
import zstandard
from mcap.reader import make_reader
from mcap.records import Chunk
from mcap.stream_reader import StreamReader

from haulprofile.analysis.cli import main
from haulprofile.contract import privacy
from haulprofile.logger.config import Config
from haulprofile.logger.emulators.rig import record_drive

from test_logger_privacy import DURATION_S, TIME_SCALE, ZONES, drive_signals, inside_epochs, needles

REDACTED_TOPICS = {"/gps/fix", "/gps/nmea", "/time/sync", "/privacy/zone"}


def every_byte(path) -> bytes:
    """The file as stored plus every chunk decompressed."""
    data = path.read_bytes()
    parts = [data]
    with open(path, "rb") as stream:
        for record in StreamReader(stream, emit_chunks=True).records:
            if isinstance(record, Chunk) and record.compression == "zstd":
                parts.append(zstandard.ZstdDecompressor().decompress(record.data,
                                                                     max_output_size=record.uncompressed_size))
            elif isinstance(record, Chunk):
                parts.append(record.data)
    return b"".join(parts)


def messages(path) -> dict[str, list]:
    out: dict[str, list] = {}
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        for _, channel, message in reader.iter_messages():
            out.setdefault(channel.topic, []).append(
                (message.log_time, message.publish_time, message.sequence, message.data))
    return out


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A drive through both zones, logged with no privacy settings (CAN, I2C and GPS)."""
    config = Config()
    config.i2c.lsm9ds1.odr_hz = 14.9
    config.i2c.lsm9ds1.mag_odr_hz = 1.25
    config.i2c.hts221.odr_hz = 1.0
    path, daemon, devices = record_drive(drive_signals(), tmp_path_factory.mktemp("plain"), duration_s=DURATION_S,
                                         time_scale=TIME_SCALE, config=config, return_rig=True)
    zones_file = path.parent.parent / "zones.toml"
    zones_file.write_text("".join(
        f'[[zones]]\nname = "{z["name"]}"\n' + "".join(f"{k} = {json.dumps(v)}\n" for k, v in z.items() if k != "name")
        for z in ZONES))
    return path, devices, zones_file


@pytest.fixture(scope="module")
def redacted(recorded, tmp_path_factory):
    path, devices, zones_file = recorded
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    out = tmp_path_factory.mktemp("redacted")
    assert main(["redact", str(path), "--zones", str(zones_file), "--out", str(out)]) == 0
    assert hashlib.sha256(path.read_bytes()).hexdigest() == digest
    return out / path.name


def removed_needles(devices) -> tuple[list[bytes], list[bytes]]:
    """(text forms, binary forms) of the coordinates and times of every epoch inside a zone."""
    zones = privacy.zones_from_tables(ZONES)
    inside, outside = inside_epochs(devices.gps.sent, zones)
    assert len(inside) >= 20 and len(outside) >= 40
    text, binary = [], []
    for msg in inside:
        text += needles(msg)[:5]
        binary += needles(msg)[5:]
    return text, binary


def test_nothing_of_the_removed_data_survives(recorded, redacted):
    path, devices, _ = recorded
    text, binary = removed_needles(devices)
    original = every_byte(path)
    assert sum(n in original for n in text) > 0.9 * len(text)  # the search can find them
    targets = text + binary
    fixes_in = [json.loads(m[3]) for m in messages(path)["/gps/fix"]]
    zones = privacy.zones_from_tables(ZONES)
    times_in = [f["gps_time_utc_ns"] for f in fixes_in if privacy.in_any(zones, f["latitude"], f["longitude"])]
    targets += [str(t).encode() for t in times_in] + [struct.pack("<q", t) for t in times_in]
    assert all(str(t).encode() in original for t in times_in)
    kept = every_byte(redacted)
    survivors = [n for n in targets if n in kept]
    assert survivors == []


def test_a_complete_readable_log_with_every_other_topic_byte_exact(recorded, redacted):
    path, _, _ = recorded
    before, after = messages(path), messages(redacted)
    with open(redacted, "rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None and summary.chunk_indexes and summary.statistics.message_count == sum(
        len(v) for v in after.values())
    others = set(before) - REDACTED_TOPICS
    assert {"/can/frames", "/imu", "/barometer", "/diagnostics"} <= others
    for topic in others:
        assert after[topic] == before[topic], topic
    zones = privacy.zones_from_tables(ZONES)
    fixes_before = [m for m in before["/gps/fix"] if not privacy.in_any(zones, *_lat_lon(m))]
    assert after["/gps/fix"] == fixes_before  # the fixes outside, as they were
    assert [json.loads(m[3])["event"] for m in after["/privacy/zone"]] == ["entered", "left", "entered", "left"]
    syncs = [json.loads(m[3]) for m in after["/time/sync"]]
    assert len(syncs) == len(before["/time/sync"]) and any(s["gps_time_utc_ns"] is None for s in syncs)
    with open(redacted, "rb") as stream:
        metadata = {m.name: m.metadata for m in make_reader(stream).iter_metadata()}
    assert "boot_id" in metadata["haulprofile.logger"]
    assert redacted.stat().st_mode & 0o777 == 0o640


def _lat_lon(message) -> tuple[float, float]:
    fix = json.loads(message[3])
    return fix["latitude"], fix["longitude"]


def test_refuses_to_write_over_its_inputs(recorded, capsys):
    path, _, zones_file = recorded
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    assert main(["redact", str(path), "--zones", str(zones_file), "--out", str(path.parent)]) == 2
    err = capsys.readouterr().err
    assert "would replace an input log" in err and err.count("\n") == 1
    assert hashlib.sha256(path.read_bytes()).hexdigest() == digest


@pytest.mark.parametrize("text, message", [
    ("", "no [[zones]]"),
    ("[[zones]]\nlat = 1\n", "zones[0]: a circle needs lat, lon and radius_m"),
    ("[[zones\n", "not valid TOML"),
])
def test_bad_zone_files_are_one_line_errors(recorded, tmp_path, capsys, text, message):
    path, _, _ = recorded
    zones = tmp_path / "zones.toml"
    zones.write_text(text)
    assert main(["redact", str(path), "--zones", str(zones), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_a_cut_log_is_refused_with_one_line(recorded, tmp_path, capsys):
    """Redaction reads with the contract's reader; a log cut by a power loss is refused (a copy
    missing its end could pass for a whole redacted log), pointing at ``analyze recover``."""
    path, _, _ = recorded
    cut = tmp_path / path.name
    whole = path.read_bytes()
    cut.write_bytes(whole[:len(whole) * 2 // 3])
    zones = tmp_path / "zones.toml"
    zones.write_text("[[zones]]\nlat = 48.137\nlon = 11.575\nradius_m = 50.0\n")
    assert main(["redact", str(cut), "--zones", str(zones), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "cut short" in err and "analyze recover" in err and err.count("\n") == 1
    assert not list((tmp_path / "out").glob("*.mcap"))
