"""Scenario files: the shipped ones load, bad ones give one line that names the problem."""

from __future__ import annotations

import pytest

from haulprofile.analysis.errors import UserError
from haulprofile.analysis.virtual_truck import SCENARIOS, load_scenario
from haulprofile.analysis.virtual_truck.scenario import ScenarioFileError

GOOD = """
[scenario]
name = "t"
vehicle = "rigid-18t"
start_latitude_deg = 47.5
start_longitude_deg = 8.5
start_time = 2025-05-14T06:30:00Z

[route]
[[route.section]]
length_m = 1000
speed_kmh = 50

[payload]
initial_kg = 2000.0
"""


@pytest.mark.parametrize("name", sorted(SCENARIOS))
def test_shipped_scenarios_load(name):
    scenario = load_scenario(name)
    assert scenario.name == name
    assert scenario.vehicle in ("rigid-18t", "tractor-40t")


def test_a_user_file_loads(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text(GOOD)
    scenario = load_scenario(path)
    assert scenario.route.section[0].speed_kmh == 50.0
    assert scenario.start_epoch_ns == 1747204200 * 10**9


@pytest.mark.parametrize("change, words", [
    (("speed_kmh = 50", "speed_kmh = 50\nspeed_mph = 30"), ["route.section", "unknown key 'speed_mph'"]),
    (("length_m = 1000\n", ""), ["missing key 'length_m'"]),
    (("speed_kmh = 50", "speed_kmh = \"fast\""), ["speed_kmh", "expected a number"]),
    (("speed_kmh = 50", "speed_kmh = 13.9e3"), ["speed_kmh = 13900", "wrong unit"]),
    (("initial_kg = 2000.0", "initial_kg = 20000.0"), ["initial_kg", "max_payload_kg"]),
    (("[payload]", "[cargo]"), ["unknown table [cargo]"]),
    (("start_time = 2025-05-14T06:30:00Z", "start_time = 2025-05-14T06:30:00"), ["start_time", "time zone"]),
    (("vehicle = \"rigid-18t\"", "vehicle = \"bus\""), ["vehicle", "bus"]),
    (("[[route.section]]", "vdri = \"nowhere.vdri\"\n[[route.section]]"), ["route", "either"]),
    (("start_latitude_deg = 47.5", "start_latitude_deg = 47.5\nstart_latitude_deg = 48"), ["not valid TOML"]),
])
def test_bad_files_give_one_line_naming_the_problem(tmp_path, change, words):
    path = tmp_path / "bad.toml"
    path.write_text(GOOD.replace(*change))
    with pytest.raises(UserError) as error:
        from haulprofile.analysis.virtual_truck import drive
        drive(load_scenario(path))
    message = str(error.value)
    assert "\n" not in message.strip()
    for word in words:
        assert word in message


def test_missing_file_names_the_shipped_scenarios(tmp_path):
    with pytest.raises(ScenarioFileError, match="urban-delivery"):
        load_scenario(tmp_path / "none.toml")


def test_a_vehicle_file_beside_the_scenario(tmp_path):
    from importlib import resources

    from haulprofile.analysis.virtual_truck import scenario_vehicle
    text = resources.files("haulprofile.analysis.data.vehicles").joinpath("tractor-40t.toml").read_text()
    (tmp_path / "my-truck.toml").write_text(text.replace('name = "Tractor-semitrailer 40 t"', 'name = "mine"'))
    path = tmp_path / "mine.toml"
    path.write_text(GOOD.replace('vehicle = "rigid-18t"', 'vehicle = "my-truck.toml"'))
    assert scenario_vehicle(load_scenario(path)).name == "mine"
