"""Inputs that hung a command or filled the memory, each refused by design before the work:
chunks that decompress past their declared size, devices and FIFOs where files belong, files
far larger than a configuration can be. Memory is judged (tracemalloc's peak), never time."""

from __future__ import annotations

import os
import struct
import tracemalloc

import lz4.frame
import numpy as np
import pytest
import zstandard

from haulprofile.contract import mcap_records

BOMB_BYTES = 256 * 1024 * 1024


def chunk_body(compression: bytes, data: bytes, size: int) -> bytes:
    head = mcap_records._CHUNK_HEAD.pack(0, 0, size, 0, len(compression))
    return head + compression + struct.pack("<Q", len(data)) + data


@pytest.fixture(scope="module")
def bombs():
    zeros = bytes(BOMB_BYTES)
    return {"zstd": zstandard.ZstdCompressor(level=3).compress(zeros), "lz4": lz4.frame.compress(zeros)}


@pytest.mark.parametrize("compression", ["zstd", "lz4"])
def test_a_chunk_never_decompresses_past_its_declared_size(bombs, compression):
    """A chunk that says 1000 bytes and holds 256 MiB of zeros (a zstd frame that declares them,
    an lz4 frame): refused as damaged with no more memory than a few chunks'."""
    body = chunk_body(compression.encode(), bombs[compression], 1000)
    tracemalloc.start()
    try:
        with pytest.raises(mcap_records.DamagedRecord):
            mcap_records._decompress(body)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 16 * 1024 * 1024, f"{peak / 1e6:.0f} MB for a 1000-byte chunk"


def test_a_chunk_declaring_gigabytes_is_damaged_not_allocated():
    body = chunk_body(b"zstd", zstandard.ZstdCompressor().compress(b"x"), 3_500_000_000)
    with pytest.raises(mcap_records.DamagedRecord, match="size field"):
        mcap_records._decompress(body)


def run_limited(argv: list[str], memory_bytes: int = 1 << 31, guard_s: float = 300.0):
    """A command line in a child process with its address space limited (reading a device would
    end in a MemoryError, not in minutes of swapping); ``guard_s`` only stops a hang from stalling
    the suite, it judges nothing."""
    import resource
    import subprocess
    import sys

    def limits():
        resource.setrlimit(resource.RLIMIT_AS, (memory_bytes, memory_bytes))

    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    return subprocess.run([sys.executable, "-c", "import sys; from {0} import main; sys.exit(main(sys.argv[1:]))"
                           .format(argv[0]), *argv[1:]], capture_output=True, text=True, preexec_fn=limits,
                          env=env, timeout=guard_s, stdin=subprocess.DEVNULL)


def one_line_error(result, code: int, words: str) -> None:
    assert result.returncode == code, result.stderr[-2000:]
    assert words in result.stderr and result.stderr.strip().count("\n") == 0, result.stderr[-2000:]


@pytest.fixture(scope="module")
def table(tmp_path_factory):
    from haulprofile.testing.drives import synthetic_drive

    path = tmp_path_factory.mktemp("table") / "drive.csv"
    synthetic_drive(300, seed=4).round(3).drop(columns=["distance_m"]).to_csv(path, index=False)
    return path


def test_devices_where_files_belong_are_refused_by_type(table, tmp_path):
    analyze = "haulprofile.analysis.cli"
    zones = tmp_path / "zones.toml"
    one_line_error(run_limited([analyze, "run", str(table), "--vehicle", "rigid-18t", "--dem", "/dev/zero",
                                "--out", str(tmp_path / "o1")]), 2, "character device")
    one_line_error(run_limited([analyze, "--identity", "/dev/zero", "info", str(table)]), 2, "character device")
    zones.write_text('[[zones]]\nname = "d"\nlat = 48.0\nlon = 11.0\nradius_m = 100\n')
    one_line_error(run_limited([analyze, "redact", str(table), "--zones", "/dev/zero", "--out", str(tmp_path / "r")]),
                   2, "character device")
    one_line_error(run_limited(["haulprofile.logger.cli", "--config", "/dev/zero", "--check"]), 2, "character device")


def test_a_fifo_input_or_log_is_refused_not_waited_on(table, tmp_path):
    fifo = tmp_path / "drive.csv"
    os.mkfifo(fifo)
    one_line_error(run_limited(["haulprofile.analysis.cli", "run", str(fifo), "--vehicle", "rigid-18t",
                                "--out", str(tmp_path / "o")]), 2, "FIFO")
    logs = tmp_path / "logs"
    logs.mkdir()
    os.mkfifo(logs / "haulprofile_0badf00d_20240514T080000Z_0007.mcap")
    config = tmp_path / "logger.toml"
    config.write_text(f'[logger]\ndirectory = "{logs}"\n')
    result = run_limited(["haulprofile.logger.cli", "--config", str(config), "--status"])
    assert result.returncode == 1 and "no logs in" in result.stdout, result.stderr[-2000:]


def test_a_huge_configuration_is_refused_by_its_size(tmp_path):
    from haulprofile.logger import config as cfg

    big = tmp_path / "logger.toml"
    with open(big, "wb") as stream:
        stream.truncate(64 * 1024 * 1024)  # sparse: no disk used
    with pytest.raises(cfg.ConfigError, match="at most"):
        cfg.load(big)


def test_a_signals_table_with_months_between_drives_is_shortened_as_logs_are(tmp_path):
    """Two drives four months apart in one CSV: the silence is shortened (as a log's is), so the
    stages resample hours, not four months at 10 Hz."""
    import numpy as np
    import pandas as pd

    from haulprofile.analysis.pipeline import RunContext, run
    from haulprofile.testing.drives import synthetic_drive

    drive = synthetic_drive(600, seed=4).round(3).drop(columns=["distance_m"])
    later = drive.assign(time_s=drive["time_s"] + 120 * 86400.0)
    table = tmp_path / "two-drives.csv"
    pd.concat([drive, later]).to_csv(table, index=False)
    said = []
    ctx = run(RunContext(inputs=[table], out_dir=tmp_path / "out", say=said.append), until="kinematics")
    time = ctx.signals["time_s"].to_numpy()
    assert len(ctx.signals) == 2 * len(drive)
    assert time[-1] - time[0] < 2 * drive["time_s"].iloc[-1] + 120.0
    assert np.all(np.diff(time) > 0)
    assert any("shortened" in line for line in said)


def test_a_geotiff_declaring_40000_squared_pixels_is_refused_from_its_header(tmp_path):
    rasterio = pytest.importorskip("rasterio")
    from haulprofile.analysis.dem import open_dem
    from haulprofile.analysis.errors import UserError

    with rasterio.open(tmp_path / "huge.tif", "w", driver="GTiff", width=40000, height=40000, count=1,
                       dtype="float32", crs="EPSG:4326", tiled=True, compress="deflate", sparse_ok=True,
                       transform=rasterio.Affine(1 / 3600, 0, 11.0, 0, -1 / 3600, 48.0)) as dst:
        dst.write(np.zeros((1, 256, 256), "float32"), window=rasterio.windows.Window(0, 0, 256, 256))
    assert (tmp_path / "huge.tif").stat().st_size < 10_000_000
    with pytest.raises(UserError, match="40000 x 40000 pixels"):
        open_dem(tmp_path)


def test_a_geotiff_without_crs_is_refused_not_taken_as_wgs84(tmp_path):
    rasterio = pytest.importorskip("rasterio")
    from haulprofile.analysis.dem import open_dem
    from haulprofile.analysis.errors import UserError

    with rasterio.open(tmp_path / "nocrs.tif", "w", driver="GTiff", width=64, height=64, count=1, dtype="float32",
                       transform=rasterio.Affine(25.0, 0, 600000.0, 0, -25.0, 5300000.0)) as dst:
        dst.write(np.full((1, 64, 64), 500.0, "float32"))
    with pytest.raises(UserError, match="coordinate reference system"):
        open_dem(tmp_path)
