"""Other loggers' files into the same pipeline: candump, Vector ASC and BLF (python-can), signals tables;
and the ``analyze info/signals/recover`` commands."""

import json

import can
import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis import cli
from haulprofile.analysis.ingest import ingest_logs
from haulprofile.testing import logs as synthetic
from haulprofile.testing.logs import BIN_NS, can_frames, make_truth

EPOCH_NS = 1_700_000_000_000_000_000


@pytest.fixture(scope="module")
def truth_and_messages():
    rng = np.random.default_rng(8)
    truth = make_truth(200, rng, t0_ns=EPOCH_NS)
    frames = can_frames(truth, filler_hz=50.0, rng=rng)
    messages = [can.Message(timestamp=int(f["t_mono_ns"]) / 1e9, arbitration_id=int(f["arbitration_id"]),
                            is_extended_id=True, dlc=8, data=f["data"].tobytes(), channel=0) for f in frames]
    return truth, messages


@pytest.mark.parametrize("suffix,writer", [(".log", can.CanutilsLogWriter), (".asc", can.ASCWriter),
                                           (".blf", can.BLFWriter)])
def test_python_can_formats(tmp_path, truth_and_messages, suffix, writer):
    truth, messages = truth_and_messages
    path = tmp_path / f"foreign{suffix}"
    with writer(str(path)) as out:
        for message in messages:
            out.on_message_received(message)
    frame, summary = ingest_logs([path])
    assert summary["can_frames"] == len(messages)
    # ASC keeps relative times only; the others carry the epoch wall clock
    n = min(len(frame), 200)
    speed = frame["speed_mps"].to_numpy()[:n]
    assert np.nanmax(np.abs(speed - truth.values["speed_mps"][:n])) <= 0.5 / 256 / 3.6 + 1e-4
    assert (frame["engine_reference_torque_nm"].dropna() == synthetic.REFERENCE_TORQUE_NM).all()
    if suffix != ".asc":
        assert abs(int(frame["wall_time_ns"].iloc[0]) - EPOCH_NS) < BIN_NS


def test_signals_table_input_passes_through(tmp_path):
    table = pd.DataFrame({"time_s": np.arange(5) * 0.1, "speed_mps": [0, 1, 2, 3, 4.0], "own_column": list("abcde")})
    path = tmp_path / "other-logger.csv"
    table.to_csv(path, index=False)
    frame, summary = ingest_logs([path])
    assert frame["own_column"].tolist() == list("abcde") and summary["source"] == "signals table"
    from haulprofile.analysis.ingest.stage import ingest_stage as stage
    from haulprofile.analysis.pipeline import RunContext

    ctx = RunContext(inputs=[path], out_dir=tmp_path, say=lambda _m: None)
    stage(ctx)
    assert ctx.signals["speed_mps"].tolist() == [0, 1, 2, 3, 4.0]


def test_commands(tmp_path, capsys):
    log = tmp_path / "log.mcap"
    with open(log, "wb") as stream:
        synthetic.write_log(stream, 12, seed=2, chunk_size=16 * 1024)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(log.read_bytes()[:-3000])
    assert cli.main(["signals", str(log), "-o", str(tmp_path / "s.parquet"), "--quiet"]) == 0
    assert len(pd.read_parquet(tmp_path / "s.parquet")) == 120
    assert cli.main(["info", str(cut), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["files"][0]["complete"] is False and summary["warnings"]
    assert cli.main(["info", str(log)]) == 0
    text = capsys.readouterr().out
    assert "/can/frames" in text and "speed_mps" in text and "complete" in text
    assert cli.main(["recover", str(cut), "-o", str(tmp_path / "fixed.mcap")]) == 0
    assert "wrote" in capsys.readouterr().out
    assert cli.main(["signals", str(tmp_path / "nope.mcap"), "-o", str(tmp_path / "x.parquet")]) == 2
    assert "not found" in capsys.readouterr().err


def test_pipeline_stage(tmp_path):
    from haulprofile.analysis.ingest.stage import ingest_stage as stage
    from haulprofile.analysis.pipeline import RunContext

    log = tmp_path / "log.mcap"
    with open(log, "wb") as stream:
        synthetic.write_log(stream, 5, seed=6)
    said = []
    ctx = RunContext(inputs=[log], out_dir=tmp_path, options={"ingest": {"rate_hz": 5.0}}, say=said.append)
    result = stage(ctx)
    assert len(ctx.signals) == 25 and result.summary()["rate_hz"] == 5.0
    assert {"speed_mps", "engine_torque_nm", "pressure_pa", "wall_time_ns"} <= set(ctx.signals.columns)
    assert said and "25 rows" in said[-1]


def test_stage_without_speed_says_so(tmp_path):
    """A log without any speed source: a one-line error naming what is missing, not a KeyError later."""
    from haulprofile.analysis.errors import UserError
    from haulprofile.analysis.ingest.stage import ingest_stage as stage
    from haulprofile.analysis.pipeline import RunContext
    from haulprofile import contract
    from haulprofile.logger.writer import LogWriter

    log = tmp_path / "baro-only.mcap"
    with open(log, "wb") as stream:
        writer = LogWriter(stream)
        for k in range(20):
            t = 10**9 + k * 40_000_000
            writer.write_json(contract.BAROMETER, {"t_mono_ns": t, "pressure_pa": 98000.0, "temperature_c": 20.0,
                                                   "pressure_raw": 0, "temperature_raw": 0}, t, t)
        writer.close()
    ctx = RunContext(inputs=[log], out_dir=tmp_path)
    with pytest.raises(UserError, match="no vehicle speed"):
        stage(ctx)


@pytest.mark.parametrize("name", ["junk.mf4", "junk.blf", "junk.asc", "junk.log"])
def test_unreadable_foreign_log_is_a_one_line_error(tmp_path, name):
    from haulprofile.analysis.errors import UserError

    path = tmp_path / name
    path.write_bytes(bytes(range(256)) * 20)
    with pytest.raises(UserError) as raised:
        ingest_logs([path])
    assert "\n" not in str(raised.value) and name in str(raised.value)


def test_a_cut_mf4_gives_one_line_and_no_traceback_from_asammdf(tmp_path):
    """asammdf's half-built reader complains from ``__del__`` after the clean error; it must not reach the user."""
    import subprocess
    import sys

    asammdf = pytest.importorskip("asammdf")
    t = np.arange(20000) * 0.01
    mdf = asammdf.MDF(version="4.10")
    mdf.append([asammdf.Signal(np.arange(20000, dtype=np.uint32), t, name="CAN_DataFrame.ID"),
                asammdf.Signal(np.full(20000, 8, np.uint8), t, name="CAN_DataFrame.DLC")])
    mdf.save(tmp_path / "full.mf4", overwrite=True)
    mdf.close()
    whole = (tmp_path / "full.mf4").read_bytes()
    (tmp_path / "cut.mf4").write_bytes(whole[:len(whole) // 2])
    result = subprocess.run([sys.executable, "-m", "haulprofile.analysis.cli", "info", str(tmp_path / "cut.mf4")],
                            capture_output=True, text=True)
    assert result.returncode == 2
    assert len(result.stderr.strip().splitlines()) == 1 and "cut.mf4" in result.stderr, result.stderr
