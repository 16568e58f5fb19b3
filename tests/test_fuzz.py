"""A fuzz suite (hypothesis) over the file parsers and the command line: whatever the bytes, a
parser returns or raises its own one-line error, never another exception, and a command exits
0, 2 or 3 with no traceback, in a child process whose memory is limited (``resource``), so that
an input that would allocate without bound fails here rather than on a user's machine."""

from __future__ import annotations

import io
import json
import os
import resource
import subprocess
import sys

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from haulprofile.contract import nmea, privacy, reader
from haulprofile.testing import logs as synthetic

FAST = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                       HealthCheck.function_scoped_fixture])
MEMORY_BYTES = 3 << 30


@pytest.fixture(scope="module")
def small_log() -> bytes:
    stream = io.BytesIO()
    synthetic.write_log(stream, 3, seed=2, chunk_size=4 * 1024)
    return stream.getvalue()


def mutated(data: bytes, draw) -> bytes:
    """``data`` with a few bytes changed, a stretch cut out, or the end cut off."""
    data = bytearray(data)
    for _ in range(draw(st.integers(0, 6))):
        at = draw(st.integers(0, len(data) - 1))
        data[at] = draw(st.integers(0, 255))
    if draw(st.booleans()):
        start = draw(st.integers(0, len(data) - 1))
        del data[start:start + draw(st.integers(0, 4096))]
    return bytes(data[:draw(st.integers(0, len(data)))] if draw(st.booleans()) else data)


@FAST
@given(st.data())
def test_the_log_reader_reads_what_it_can_from_any_damage(small_log, data):
    report = reader.ReadReport("fuzz")
    messages = list(reader.read_messages(mutated(small_log, data.draw), report))
    assert all(m.channel is not None for m in messages)


@FAST
@given(st.lists(st.text(alphabet=st.characters(min_codepoint=1, max_codepoint=0x7f)).map(lambda s: "$" + s),
                max_size=30))
def test_nmea_sentences_of_any_text_are_counted_not_raised(lines):
    counts: dict = {}
    fixes = []
    epochs = nmea.EpochFixes(lambda epoch, fix: fixes.append(fix), counts)
    for t, line in enumerate(lines):
        epochs.sentence(line, t)
    epochs.flush()
    assert all(f is None or -90 <= f["latitude"] <= 90 for f in fixes)


JSON_VALUES = st.recursive(st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8),
                           lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner,
                                                                                     max_size=4), max_leaves=12)


@FAST
@given(st.lists(st.dictionaries(st.sampled_from(["name", "lat", "lon", "radius_m", "polygon", "x"]), JSON_VALUES,
                                max_size=5), max_size=3))
def test_zone_tables_of_any_shape_are_one_value_error(tables):
    try:
        zones = privacy.zones_from_tables(tables)
    except ValueError as exc:
        assert "\n" not in str(exc)
    else:
        assert all(z.radius_m > 0 or len(z.polygon) >= 3 for z in zones)


TOML_TEXT = st.text(alphabet=st.sampled_from(list("[]=\"'.,{}#\n abcdefgilmnoprstuxyz0123456789_-+")), max_size=200)


@FAST
@given(TOML_TEXT)
def test_a_logger_configuration_of_any_text_is_one_config_error(tmp_path_factory, text):
    from haulprofile.logger import config as cfg

    path = tmp_path_factory.mktemp("cfg") / "logger.toml"
    path.write_text(text)
    try:
        cfg.load(path)
    except cfg.ConfigError as exc:
        assert "\n" not in str(exc).strip()


CSV_CELLS = st.sampled_from(["0", "1.5", "-3", "nan", "inf", "", "x", "1e308", "-1e308", "12:00", "99999999999999999999"])


@FAST
@given(st.lists(st.sampled_from(["time_s", "speed_mps", "pressure_pa", "engine_torque_nm", "latitude_deg", "foo"]),
                min_size=1, max_size=5, unique=True),
       st.lists(st.lists(CSV_CELLS, min_size=5, max_size=5), max_size=12))
def test_a_signals_table_of_any_cells_is_one_signals_error(tmp_path_factory, columns, rows):
    from haulprofile.analysis.errors import UserError
    from haulprofile.analysis.signals import read_signals

    path = tmp_path_factory.mktemp("csv") / "t.csv"
    path.write_text(",".join(columns) + "\n" + "".join(",".join(r[:len(columns)]) + "\n" for r in rows))
    try:
        frame = read_signals(path)
    except UserError as exc:
        assert "\n" not in str(exc)
    else:
        assert len(frame) >= 2


def limited_run(argv: list[str]) -> subprocess.CompletedProcess:
    def limits():
        resource.setrlimit(resource.RLIMIT_AS, (MEMORY_BYTES, MEMORY_BYTES))
        resource.setrlimit(resource.RLIMIT_CPU, (120, 120))  # a guard: a loop is killed, not judged

    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    return subprocess.run([sys.executable, "-m", "haulprofile.analysis.cli", *argv], capture_output=True, text=True,
                          preexec_fn=limits, env=env, stdin=subprocess.DEVNULL)


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                  HealthCheck.function_scoped_fixture])
@given(st.data())
def test_the_command_line_on_damaged_logs_exits_with_a_line_not_a_traceback(small_log, tmp_path_factory, data):
    folder = tmp_path_factory.mktemp("cli")
    log = folder / "damaged.mcap"
    log.write_bytes(mutated(small_log, data.draw))
    command = data.draw(st.sampled_from([["info", str(log)], ["recover", str(log), "-o", str(folder / "r.mcap")],
                                         ["signals", str(log), "-o", str(folder / "s.csv")]]))
    result = limited_run(command)
    assert result.returncode in (0, 2, 3), (command, result.stderr[-3000:])
    assert "Traceback" not in result.stderr, (command, result.stderr[-3000:])
    if result.returncode == 2:  # one error line (progress lines such as "[ingest]" may precede it)
        assert sum("error:" in line for line in result.stderr.splitlines()) == 1, result.stderr[-3000:]


def test_the_fuzzed_json_topics_handle_integers_beyond_int64(tmp_path):
    """A JSON topic record with an integer beyond int64 (``t_mono_ns``): a damaged record, not a traceback."""
    from haulprofile.analysis.cli import main
    from haulprofile.logger.writer import LogWriter
    from haulprofile import contract

    path = tmp_path / "big-ints.mcap"
    with open(path, "wb") as stream:
        writer = LogWriter(stream)
        for i in range(5):
            record = {"t_mono_ns": (1 << 70) if i == 2 else i * 10 ** 9, "pressure_pa": 101325.0,
                      "temperature_c": 20.0}
            writer.write(contract.BAROMETER, json.dumps(record).encode(), i * 10 ** 9, i * 10 ** 9)
        writer.close()
    assert main(["info", str(path)]) in (0, 2, 3)
