"""The wheel installs one top-level package, ``haulprofile``, and lives beside another
distribution's ``logger`` package in a fresh environment."""

import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def pip(*args, cwd):
    return subprocess.run([sys.executable, "-m", "pip", *args], cwd=cwd, check=True, capture_output=True,
                          text=True).stdout


@pytest.mark.slow
def test_wheel_installs_one_top_level_package_beside_a_foreign_logger(tmp_path):
    source = tmp_path / "source"
    for folder in ("logger", "analysis"):  # the design's folders, installed under haulprofile
        shutil.copytree(ROOT / folder, source / folder,
                        ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.nbi", "*.nbc"))
    for name in ("pyproject.toml", "setup.py", "README.md"):
        shutil.copy(ROOT / name, source / name)
    foreign = tmp_path / "foreign"
    (foreign / "logger").mkdir(parents=True)
    (foreign / "logger" / "__init__.py").write_text('NAME = "somebody else\'s logger"\n')
    (foreign / "pyproject.toml").write_text('[build-system]\nrequires = ["setuptools>=69"]\n'
                                            'build-backend = "setuptools.build_meta"\n'
                                            '[project]\nname = "logger"\nversion = "0.0.1"\n')
    pip("wheel", "--no-deps", "-q", "-w", str(tmp_path / "dist"), str(source), cwd=tmp_path)
    wheel = next((tmp_path / "dist").glob("haulprofile-*.whl"))

    env = tmp_path / "env"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(env)], check=True)
    python = env / "bin" / "python"
    pip("--python", str(python), "install", "-q", "--no-deps", str(foreign), str(wheel), cwd=tmp_path)
    site = Path(subprocess.run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                               check=True, capture_output=True, text=True).stdout.strip())
    # the dependencies come from this test environment (no downloads), after the fresh site-packages
    (site / "test-dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")

    files = [line.strip() for line in pip("--python", str(python), "show", "-f", "haulprofile",
                                          cwd=tmp_path).split("Files:", 1)[1].splitlines() if line.strip()]
    dist_info = wheel.name.split("-py3")[0] + ".dist-info"
    assert {f.split("/")[0] for f in files if not f.startswith("../")} == {"haulprofile", dist_info}
    assert (site / dist_info / "top_level.txt").read_text().split() == ["haulprofile"]

    check = ("import logger, haulprofile, haulprofile.contract, haulprofile.analysis.cli, haulprofile.logger.cli\n"
             "print(logger.NAME)\n"
             "print(haulprofile.contract.__file__)\n"
             "from haulprofile import analysis\n"
             "print(analysis.simulate_cycle.__name__)\n")
    out = subprocess.run([python, "-c", check], cwd=tmp_path, check=True, capture_output=True, text=True).stdout
    lines = out.splitlines()
    assert lines[0] == "somebody else's logger"
    assert Path(lines[1]).is_relative_to(site)
    assert lines[2] == "simulate_cycle"
