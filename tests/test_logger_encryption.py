"""Encryption at rest (age via pyrage): closed logs become .mcap.age for the fleet's public key, the
plaintext goes only after the ciphertext is fsynced, a power cut's file is repaired and then
encrypted at the next start, and ``analyze --identity`` reads the result."""

from __future__ import annotations

import shutil

import pytest
from mcap.reader import make_reader

pyrage = pytest.importorskip("pyrage")

from haulprofile.analysis.cli import main  # noqa: E402
from haulprofile.analysis.ingest.recover import recover  # noqa: E402
from haulprofile.logger import encryption  # noqa: E402
from haulprofile.logger import config as cfg  # noqa: E402
from haulprofile.logger.emulators.rig import record_drive  # noqa: E402
from haulprofile.logger.emulators.signals import synthetic_drive  # noqa: E402
from haulprofile.contract.repair import is_complete  # noqa: E402


@pytest.fixture(scope="module")
def fleet_key(tmp_path_factory):
    identity = pyrage.x25519.Identity.generate()
    path = tmp_path_factory.mktemp("workstation") / "fleet.key"
    path.write_text(f"# fleet identity: stays on the workstation\n{identity}\n")
    return identity, str(identity.to_public()), path


def light_config(recipient: str) -> cfg.Config:
    config = cfg.from_dict({"encryption": {"recipients": [recipient]}})
    config.i2c.lsm9ds1.odr_hz = 14.9
    config.i2c.lsm9ds1.mag_odr_hz = 1.25
    config.i2c.hts221.odr_hz = 1.0
    return config


def decrypt(path, identity) -> bytes:
    return pyrage.decrypt(path.read_bytes(), [identity])


@pytest.fixture(scope="module")
def encrypted_run(fleet_key, tmp_path_factory):
    identity, recipient, _ = fleet_key
    out = tmp_path_factory.mktemp("pi") / "logs"
    path, daemon, _ = record_drive(synthetic_drive(10.0), out, duration_s=3.0, config=light_config(recipient),
                                   return_rig=True)
    return out, daemon


def test_closed_logs_are_encrypted_and_the_plaintext_is_gone(encrypted_run, fleet_key, tmp_path):
    out, daemon = encrypted_run
    identity, recipient, _ = fleet_key
    files = sorted(p.name for p in out.iterdir() if not p.name.startswith("."))
    assert len(files) == 1 and files[0].endswith(".mcap.age")
    age = out / files[0]
    assert age.read_bytes().startswith(b"age-encryption.org/v1\n-> X25519 ")
    assert age.stat().st_mode & 0o777 == 0o640
    plain = tmp_path / files[0][:-4]
    plain.write_bytes(decrypt(age, identity))
    with open(plain, "rb") as stream:
        reader = make_reader(stream)
        topics = {channel.topic for _, channel, _ in reader.iter_messages()}
        assert reader.get_summary().statistics.message_count > 50  # sensors batched since contract 2
    assert {"/can/frames", "/imu", "/gps/fix", "/time/sync"} <= topics
    with pytest.raises(pyrage.DecryptError):  # nothing on the Pi decrypts it: it holds only the recipient
        pyrage.decrypt(age.read_bytes(), [pyrage.x25519.Identity.generate()])
    assert "AGE-SECRET-KEY" not in repr(daemon.config) and daemon.encryptor.errors == 0


def test_analyze_reads_encrypted_logs_with_the_identity(encrypted_run, fleet_key, capsys):
    out, _ = encrypted_run
    _, _, key_file = fleet_key
    assert main(["info", str(out), "--identity", str(key_file)]) == 0
    assert "/gps/fix" in capsys.readouterr().out
    assert main(["info", str(out)]) == 2
    err = capsys.readouterr().err
    assert "is encrypted (age): give the fleet's identity with --identity FILE" in err and err.count("\n") == 1
    wrong = key_file.with_name("other.key")
    wrong.write_text(f"{pyrage.x25519.Identity.generate()}\n")
    assert main(["--identity", str(wrong), "info", str(out)]) == 2
    assert "cannot decrypt with the given identity" in capsys.readouterr().err


def test_a_power_cut_file_is_repaired_then_encrypted_at_the_next_start(encrypted_run, fleet_key, tmp_path):
    """A file cut mid-chunk (as a power cut leaves it), a ciphertext cut short beside another log,
    and a log whose plaintext outlived its finished ciphertext, all found at start."""
    out, _ = encrypted_run
    identity, recipient, _ = fleet_key
    logs = tmp_path / "logs"
    logs.mkdir()
    source = next(out.glob("*.mcap.age"))
    whole = decrypt(source, identity)
    cut = logs / "haulprofile_0badf00d_20240514T080000Z_0007.mcap"
    cut.write_bytes(whole[:int(len(whole) * 0.6)])
    reference = tmp_path / "reference.mcap"
    expected = recover(cut, reference).messages  # what `analyze recover` gets out of the cut file
    (logs / (cut.name + ".age.partial")).write_bytes(b"age-encryption.org/v1\n-> X25519 cut")
    done = logs / "haulprofile_0badf00d_20240514T070000Z_0006.mcap"
    done.write_bytes(whole)
    shutil.copy(source, done.with_name(done.name + ".age"))
    record_drive(synthetic_drive(5.0), logs, duration_s=1.0, config=light_config(recipient))
    names = sorted(p.name for p in logs.iterdir() if not p.name.startswith("."))
    assert all(n.endswith(".mcap.age") for n in names) and len(names) == 3, names
    repaired = tmp_path / "repaired.mcap"
    repaired.write_bytes(decrypt(logs / (cut.name + ".age"), identity))
    assert is_complete(repaired)
    with open(repaired, "rb") as stream:
        reader = make_reader(stream)
        assert reader.get_summary() is not None
        assert sum(1 for _ in reader.iter_messages()) == expected > 20
    assert decrypt(done.with_name(done.name + ".age"), identity) == whole


def test_plaintext_is_removed_only_after_the_ciphertext_is_durable(fleet_key, tmp_path, monkeypatch):
    identity, recipient, _ = fleet_key
    log = tmp_path / "haulprofile_0badf00d_20240514T080000Z_0001.mcap"
    log.write_bytes(b"\x89MCAP0\r\n" + b"x" * 5000 + b"\x89MCAP0\r\n")
    events = []
    real_fsync, real_replace, real_unlink = encryption.os.fsync, encryption.os.replace, type(log).unlink
    monkeypatch.setattr(encryption.os, "fsync", lambda fd: (events.append("fsync"), real_fsync(fd))[1])
    monkeypatch.setattr(encryption.os, "replace", lambda a, b: (events.append("replace"), real_replace(a, b))[1])
    monkeypatch.setattr(type(log), "unlink", lambda self, missing_ok=False: (
        events.append(f"unlink {self.name}"), real_unlink(self, missing_ok=missing_ok))[1])
    target = encryption.encrypt_log(log, encryption.parse_recipients([recipient]))
    plain_removed = events.index(f"unlink {log.name}")
    assert events[:3] == ["fsync", "replace", "fsync"] and plain_removed > 2  # file, rename, directory
    assert not log.exists() and pyrage.decrypt(target.read_bytes(), [identity]) == b"\x89MCAP0\r\n" + b"x" * 5000 \
        + b"\x89MCAP0\r\n"


def test_bad_recipients_are_one_line_config_errors():
    with pytest.raises(cfg.ConfigError, match=r"encryption.recipients\[0\] is not an age or SSH public key"):
        cfg.from_dict({"encryption": {"recipients": ["age1notakey"]}})


def linear_message_count(path) -> int:
    """Messages mcap's own linear reader yields before a cut (an independent count)."""
    import struct

    from mcap.exceptions import McapError
    from mcap.records import Message
    from mcap.stream_reader import StreamReader
    count = 0
    with open(path, "rb") as stream:
        try:
            for record in StreamReader(stream, skip_magic=False).records:
                count += isinstance(record, Message)
        except (McapError, EOFError, ValueError, KeyError, struct.error):  # the cut
            pass
    return count


def test_repair_survives_a_cut_anywhere(encrypted_run, fleet_key, tmp_path):
    """A power cut can end a file inside any record, even inside a length field; the repaired file
    keeps every message of every complete chunk (as mcap's linear reader counts them) and the
    logger's metadata record."""
    from haulprofile.contract.repair import repair
    out, _ = encrypted_run
    identity, _, _ = fleet_key
    whole = decrypt(next(out.glob("*.mcap.age")), identity)
    cut = tmp_path / "cut.mcap"
    for end in range(9, len(whole), max(1, len(whole) // 40)):
        for extra in (0, 3, 5):
            cut.write_bytes(whole[:end + extra])
            read = linear_message_count(cut)
            expected = recover(cut, tmp_path / "reference.mcap").messages if read else 0
            assert repair(cut) == read == expected
            assert is_complete(cut)
            if read:
                with open(cut, "rb") as stream:
                    names = [m.name for m in make_reader(stream).iter_metadata()]
                assert "haulprofile.logger" in names


def _fixes(path) -> list[dict]:
    import json
    with open(path, "rb") as stream:
        return [json.loads(m.data) for _, c, m in make_reader(stream).iter_messages() if c.topic == "/gps/fix"]


def test_redact_reads_encrypted_logs_and_writes_plain_copies(encrypted_run, fleet_key, tmp_path, capsys):
    """The drive starts from standstill and speeds up: a zone around its first logged fix, reaching
    half way to its last, takes out the first fixes (where the first fix falls depends on how soon
    the GPS task ran on this machine, so the zone is placed from the log)."""
    from haulprofile.contract.privacy import distance_m
    out, _ = encrypted_run
    identity, _, key_file = fleet_key
    original = tmp_path / "original.mcap"
    original.write_bytes(decrypt(next(out.glob("*.mcap.age")), identity))
    logged = _fixes(original)
    first, last = logged[0], logged[-1]
    radius_m = 0.5 * distance_m(first["latitude"], first["longitude"], last["latitude"], last["longitude"])
    assert radius_m > 0.1, "the truck moved while it was logged"
    zones = tmp_path / "zones.toml"
    zones.write_text(f"[[zones]]\nname = \"depot\"\nlat = {first['latitude']!r}\nlon = {first['longitude']!r}\n"
                     f"radius_m = {radius_m!r}\n")
    redacted = tmp_path / "redacted"
    assert main(["--identity", str(key_file), "redact", str(out), "--zones", str(zones), "--out", str(redacted)]) == 0
    (copy,) = [p for p in redacted.iterdir() if not p.name.startswith(".")]  # not the manifest
    assert copy.name.endswith(".mcap") and not copy.name.endswith(".age")
    first_outside = next(i for i, f in enumerate(logged)
                         if distance_m(first["latitude"], first["longitude"], f["latitude"], f["longitude"]) > radius_m)
    assert 0 < first_outside < len(logged) and _fixes(copy) == logged[first_outside:]
    assert "1 stretch(es) in zones" in capsys.readouterr().out
