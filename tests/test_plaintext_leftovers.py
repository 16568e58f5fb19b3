"""No plaintext of an encrypted log, and no run's files, stay behind in the temporary folder: the
decrypted log lives in memory (gone with the process, SIGKILL included), and ``analysis.run``
without ``out`` removes the folder it wrote into."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

pyrage = pytest.importorskip("pyrage")

PLAINTEXT = b"\x89MCAP0\r\n" + b"positions of a driver " * 4000

CHILD = """
import sys, time
from haulprofile.analysis import encrypted
encrypted.use_identity_file(sys.argv[1])
path = encrypted.decrypted(sys.argv[2])
assert path.read_bytes().startswith(b"\\x89MCAP0")
print(path, flush=True)
time.sleep(60)
"""


def left_behind(tmp: Path) -> list[Path]:
    """Regular files (not links) anywhere under the temporary folder holding the plaintext."""
    return [p for p in tmp.rglob("*") if p.is_file() and not p.is_symlink() and PLAINTEXT[:64] in p.read_bytes()]


@pytest.mark.parametrize("signum", [signal.SIGKILL, signal.SIGTERM, signal.SIGHUP])
def test_a_killed_run_leaves_no_plaintext_in_the_temporary_folder(tmp_path, signum):
    identity = pyrage.x25519.Identity.generate()
    key = tmp_path / "fleet.key"
    key.write_text(f"{identity}\n")
    log = tmp_path / "logs" / "truck.mcap.age"
    log.parent.mkdir()
    log.write_bytes(pyrage.encrypt(PLAINTEXT, [identity.to_public()]))
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    env = {**os.environ, "TMPDIR": str(tmp), "PYTHONPATH": os.pathsep.join(sys.path)}
    child = subprocess.Popen([sys.executable, "-c", CHILD, str(key), str(log)], stdout=subprocess.PIPE, env=env)
    opened = Path(child.stdout.readline().decode().strip())
    assert opened.name == "truck.mcap", "the readers see the plain name"
    child.send_signal(signum)
    child.wait(timeout=60)
    assert left_behind(tmp) == []
    if signum != signal.SIGKILL:
        assert list(tmp.iterdir()) == [], "the folder of links goes too"
    subprocess.run([sys.executable, "-c", "from haulprofile.analysis import encrypted; encrypted._workdir()"],
                   env=env, check=True)
    assert [p for p in tmp.iterdir() if str(child.pid) in p.name] == [], "a killed run's folder is swept"


def test_api_run_without_out_leaves_no_temporary_folder(tmp_path, monkeypatch):
    from haulprofile import analysis
    from haulprofile.testing.drives import synthetic_drive

    table = tmp_path / "drive.csv"
    synthetic_drive(600, seed=4).round(3).drop(columns=["distance_m"]).to_csv(table, index=False)
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setenv("TMPDIR", str(tmp))
    import tempfile
    monkeypatch.setattr(tempfile, "tempdir", None)
    result = analysis.run(table, vehicle="rigid-18t", until="kinematics")
    assert len(result.signals) > 0 and result.summary["stages"]
    assert list(tmp.iterdir()) == []
