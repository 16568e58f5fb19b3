"""What a new or hostile user meets: no command writes over an input or a log, bad values are one
line and exit 2, a result that is not trustworthy exits 3, one option vocabulary."""

import errno

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis import cli
from haulprofile.testing import logs as synthetic


def run_cli(capsys, *argv):
    code = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def one_line_error(code, err, *words):
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "error" in lines[0] and "Traceback" not in err, err
    for word in words:
        assert word in lines[0], err


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    path = tmp_path_factory.mktemp("logs") / "log.mcap"
    with open(path, "wb") as stream:
        synthetic.write_log(stream, 6, seed=3, chunk_size=16 * 1024)
    return path


@pytest.fixture
def table(tmp_path):
    """A valid 60 s signals table at 10 Hz (speed only)."""
    time = np.arange(600) * 0.1
    path = tmp_path / "drive.csv"
    pd.DataFrame({"time_s": time, "speed_mps": 10 + 5 * np.sin(time / 10)}).to_csv(path, index=False)
    return path


# -- data loss --------------------------------------------------------------------------------
def test_signals_never_writes_over_its_input_log(log, capsys):
    before = log.read_bytes()
    code, _, err = run_cli(capsys, "signals", log, "-o", log)
    one_line_error(code, err, str(log))
    assert log.read_bytes() == before


def test_recover_never_writes_over_an_existing_log(log, tmp_path, capsys):
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(log.read_bytes()[:-2000])
    existing = tmp_path / "complete.mcap"
    existing.write_bytes(log.read_bytes())
    code, _, err = run_cli(capsys, "recover", cut, "-o", existing)
    one_line_error(code, err, "existing log")
    assert existing.read_bytes() == log.read_bytes()
    renamed = tmp_path / "complete.bin"  # a log is known by its bytes, not only its suffix
    existing.rename(renamed)
    code, _, err = run_cli(capsys, "recover", cut, "-o", renamed)
    one_line_error(code, err)


def test_signals_refuses_an_unknown_output_suffix(log, tmp_path, capsys):
    code, _, err = run_cli(capsys, "signals", log, "-o", tmp_path / "x.txt")
    one_line_error(code, err, ".txt")
    assert not (tmp_path / "x.txt").exists()


@pytest.mark.parametrize("command", ["run", "gradient", "fleet", "cycle"])
def test_out_an_existing_file_is_one_line(command, table, tmp_path, capsys):
    target = tmp_path / "a-file"
    target.write_text("keep me")
    extra = {"run": ["--vehicle", "rigid-18t"], "fleet": ["--vehicle", "rigid-18t"], "cycle": ["--mass-kg", "20000"]}
    inputs = [table.parent] if command == "fleet" else [table]
    code, _, err = run_cli(capsys, command, *inputs, "--out", target, *extra.get(command, []))
    one_line_error(code, err, "existing file")
    assert target.read_text() == "keep me"


def test_a_refusal_of_the_file_system_is_one_line_not_an_internal_error(table, tmp_path, capsys, monkeypatch):
    """A read-only directory (EACCES/EROFS) is the user's to fix: exit 2, one line naming the file."""
    from haulprofile.analysis import signals

    def read_only(frame, path, **_):
        raise PermissionError(errno.EACCES, "Permission denied", str(path))

    monkeypatch.setattr(pd.DataFrame, "to_parquet", read_only)
    code, _, err = run_cli(capsys, "run", table, "--vehicle", "rigid-18t", "--out", tmp_path / "ro",
                           "--candidates", "10")
    one_line_error(code, err, "Permission denied", "signals.parquet")
    assert signals  # the table writer is the one refused


# -- sizes and values --------------------------------------------------------------------------
@pytest.mark.parametrize("rate", ["0", "-5", "1e6", "nan"])
def test_rates_out_of_range_are_refused(rate, log, tmp_path, capsys):
    code, _, err = run_cli(capsys, "signals", log, "-o", tmp_path / "s.parquet", "--rate-hz", rate)
    one_line_error(code, err, "--rate-hz")


def test_a_cycle_of_1e9_seconds_is_refused_before_allocating(table, tmp_path, capsys):
    code, _, err = run_cli(capsys, "cycle", table, "--out", tmp_path / "o", "--mass-kg", "20000",
                           "--duration", "1e9")
    one_line_error(code, err, "--cycle-duration")


@pytest.mark.parametrize("payload", ["-5000", "nan"])
def test_impossible_payloads_are_refused(payload, table, tmp_path, capsys):
    code, _, err = run_cli(capsys, "run", table, "--vehicle", "rigid-18t", "--out", tmp_path / "o",
                           "--payload-kg", payload)
    one_line_error(code, err, "--payload-kg")
    code, _, err = run_cli(capsys, "simulate", table, "--vehicle", "rigid-18t", "--out", tmp_path / "o",
                           "--payload-kg", payload)
    one_line_error(code, err, "--payload-kg")


def test_forgetting_factor_above_one_is_refused(table, tmp_path, capsys):
    code, _, err = run_cli(capsys, "mass", table, "--vehicle", "rigid-18t", "--out", tmp_path / "o",
                           "--forgetting-factor", "2")
    one_line_error(code, err, "--forgetting-factor")


def test_simulate_on_random_bytes_and_a_file_as_aux_power(table, tmp_path, capsys):
    noise = tmp_path / "noise.csv"
    noise.write_bytes(np.random.default_rng(0).bytes(5000))
    code, _, err = run_cli(capsys, "simulate", noise, "--vehicle", "rigid-18t", "--out", tmp_path / "o")
    one_line_error(code, err, "noise.csv")
    toml = tmp_path / "aux.toml"
    toml.write_text("[x]\ny = 1\n")
    code, _, err = run_cli(capsys, "simulate", table, "--vehicle", "rigid-18t", "--out", tmp_path / "o",
                           "--aux-power-w", toml)
    one_line_error(code, err, "--aux-power-w")


def test_a_vehicle_file_of_invalid_bytes_is_one_line(table, tmp_path, capsys):
    vehicle = tmp_path / "truck.toml"
    vehicle.write_bytes(b"curb_mass_kg = \xff\xfe\x00 12000\n")
    code, _, err = run_cli(capsys, "simulate", table, "--vehicle", vehicle, "--out", tmp_path / "o")
    one_line_error(code, err, "truck.toml")


# -- exit codes ---------------------------------------------------------------------------------
def test_run_on_speed_only_exits_3_when_mass_and_cycle_were_skipped(table, tmp_path, capsys):
    code, out, err = run_cli(capsys, "run", table, "--vehicle", "rigid-18t", "--out", tmp_path / "o",
                             "--candidates", "10", "--quiet")
    assert code == 3, err
    assert "mass" in err and "cycle" in err and len(err.strip().splitlines()) == 1


# -- outputs and vocabulary ------------------------------------------------------------------
def test_info_on_a_signals_table_gives_its_duration_rate_and_validity(table, capsys):
    code, out, _ = run_cli(capsys, "info", table)
    assert code == 0
    assert "duration 60.0 s, 600 rows at 10 Hz, 100.0% valid" in out and "speed_mps" in out


def test_old_option_spellings_work_and_are_hidden(log, tmp_path, capsys):
    assert cli.main(["signals", str(log), "--output", str(tmp_path / "a.csv"), "--rate", "5", "--quiet"]) == 0
    assert len(pd.read_csv(tmp_path / "a.csv")) == 30
    for command, hidden, shown in (("signals", ["--output", "--rate "], ["--out", "--rate-hz"]),
                                   ("cycle", ["--duration", "--output"], ["--cycle-duration", "-o OUT, --out OUT"]),
                                   ("run", ["--rate ", "--duration", "--output"], ["--rate-hz", "--cycle-duration"])):
        with pytest.raises(SystemExit):
            cli.main([command, "--help"])
        text = capsys.readouterr().out
        assert all(h not in text for h in hidden) and all(s in text for s in shown), text


def test_version(capsys):
    with pytest.raises(SystemExit) as exit_info:
        cli.main(["--version"])
    assert exit_info.value.code == 0 and capsys.readouterr().out.startswith("analyze (haulprofile) ")


@pytest.mark.parametrize("command", ["run", "simulate"])
def test_time_in_the_wrong_unit_is_refused_before_allocating(command, tmp_path, capsys):
    """time_s x 1e12 asked for 7 PiB; a table in ms is refused as well."""
    time = np.arange(600) * 0.1
    for scale in (1e12, 1e3):
        path = tmp_path / f"x{scale:g}.csv"
        pd.DataFrame({"time_s": time * scale, "speed_mps": np.full(600, 10.0)}).to_csv(path, index=False)
        code, _, err = run_cli(capsys, command, path, "--vehicle", "rigid-18t", "--out", tmp_path / "o")
        one_line_error(code, err, "seconds")


def test_stages_check_their_sizes_before_allocating():
    """Behind the validator, the stages that allocate by time or distance refuse absurd sizes themselves."""
    from haulprofile.analysis.errors import UserError
    from haulprofile.analysis.gradient import GradientSettings, estimate_gradient
    from haulprofile.analysis.simulate import simulate_cycle
    from haulprofile.analysis.simulate.cycle import time_cycle
    from haulprofile.analysis.vehicle import load_vehicle

    vehicle = load_vehicle("rigid-18t")
    far = pd.DataFrame({"time_s": [0.0, 1e13], "speed_mps": [10.0, 10.0]})
    with pytest.raises(UserError, match="rows"):
        simulate_cycle(time_cycle(far, 20_000.0), vehicle)
    with pytest.raises(UserError, match="distance grid"):
        estimate_gradient(far.assign(distance_m=[0.0, 1e12], pressure_pa=[95_000.0, 95_000.0]), None,
                          GradientSettings())


def test_mass_without_a_confident_segment_exits_3(tmp_path, capsys):
    """A steady cruise has no excitation: the command finishes but says the result is not trustworthy."""
    time = np.arange(3000) * 0.1
    path = tmp_path / "cruise.csv"
    pd.DataFrame({"time_s": time, "speed_mps": 15.0, "engine_speed_rpm": 1400.0, "engine_torque_nm": 600.0,
                  "gradient_pct": 0.0}).to_csv(path, index=False)
    code, _, err = run_cli(capsys, "mass", path, "--vehicle", "rigid-18t", "--out", tmp_path / "o", "--no-figure")
    assert code == 3 and "confident mass" in err
