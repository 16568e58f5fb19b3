"""The demo's kernel warm-up: a stamp per state of the sources, a process that can only save time
and leaves nothing behind when the demo stops it."""

import sys
import time

import numba
import pytest

from haulprofile.analysis import warmup
from haulprofile.analysis.cli import main
from haulprofile.analysis.virtual_truck import load_scenario


@pytest.fixture
def package(tmp_path, monkeypatch):
    """A package tree of one source file and a numba cache directory, both of this test's own."""
    tree = tmp_path / "package"
    (tree / "analysis").mkdir(parents=True)
    (tree / "analysis" / "kernels.py").write_text("x = 1\n")
    monkeypatch.setattr(warmup, "PACKAGE_DIR", tree)
    monkeypatch.setattr(numba.config, "CACHE_DIR", str(tmp_path / "numba-cache"))
    return tree


def test_a_finished_warmup_is_not_repeated_until_a_source_changes(package):
    assert warmup.needed()
    warmup.stamp_path().parent.mkdir(parents=True)
    warmup.stamp_path().touch()
    assert not warmup.needed()
    assert warmup.start(load_scenario("regional-tunnel"), "typical") is None, "no process when nothing to compile"
    (package / "analysis" / "kernels.py").write_text("x = 22\n")
    assert warmup.needed()


def test_the_stamp_lies_beside_the_kernels_when_numba_has_no_cache_directory(package, monkeypatch):
    monkeypatch.setattr(numba.config, "CACHE_DIR", "")
    assert warmup.stamp_path().parent == package / "analysis" / "__pycache__"


def test_a_stopped_warmup_leaves_no_work_folder(tmp_path, monkeypatch):
    """Stopped while it works, the process ends and removes its temporary folder."""
    work_root = tmp_path / "tmp"
    work_root.mkdir()
    monkeypatch.setenv("TMPDIR", str(work_root))
    monkeypatch.setattr(warmup, "needed", lambda: True)
    process = warmup.start(load_scenario("regional-tunnel"), "typical")
    assert process is not None and process.args[:3] == [sys.executable, "-m", "haulprofile.analysis.warmup"]
    while process.poll() is None and not list(work_root.glob("haulprofile-warmup-*")):
        time.sleep(0.05)
    assert process.poll() is None, "the warm-up ended before its work folder was seen"
    warmup.stop(process)
    assert process.returncode is not None
    assert not list(work_root.iterdir())
    warmup.stop(process)  # a second stop does nothing


def test_the_demo_refuses_a_design_search_too_small_to_run(tmp_path, capsys):
    code = main(["demo", "--out", str(tmp_path / "out"), "--design-population", "2"])
    err = capsys.readouterr().err
    assert code == 2 and "--design-population must be at least 4" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()
