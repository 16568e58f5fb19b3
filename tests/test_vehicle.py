import pytest

from haulprofile.analysis.vehicle import EXAMPLES, VehicleFileError, load_vehicle


@pytest.mark.parametrize("name", list(EXAMPLES))
def test_examples_load(name):
    vehicle = load_vehicle(name)
    assert vehicle.curb_mass_kg > 5000
    assert vehicle.electric_powertrain is not None
    assert len(vehicle.total_ratios) == len(vehicle.gear_ratios)


def test_rigid_is_the_papers_daf():
    assert load_vehicle("rigid-18t").curb_mass_kg == 8818.8


GOOD = """
[vehicle]
name = "t"
curb_mass_kg = 9000
drag_coefficient = 0.6
frontal_area_m2 = 9
rolling_resistance_coefficient = 0.006
wheel_radius_m = 0.5
driveline_efficiency = 0.93
"""


def write(tmp_path, text):
    path = tmp_path / "v.toml"
    path.write_text(text)
    return path


def test_minimal_file_written_by_another_tool_loads(tmp_path):
    vehicle = load_vehicle(write(tmp_path, GOOD))
    assert vehicle.gear_ratios is None and vehicle.electric_powertrain is None


@pytest.mark.parametrize("text, words", [
    (GOOD.replace("drag_coefficient", "drag_coeficient"), ["unknown key 'drag_coeficient'"]),
    (GOOD.replace("wheel_radius_m = 0.5", ""), ["missing key 'wheel_radius_m'"]),
    (GOOD.replace("wheel_radius_m = 0.5", "wheel_radius_m = 492"), ["wheel_radius_m", "wrong unit"]),
    (GOOD.replace("curb_mass_kg = 9000", 'curb_mass_kg = "9 t"'), ["curb_mass_kg", "expected a number"]),
    (GOOD + "gear_ratios = [3.0, -1]\naxle_ratio = 3\n", ["gear_ratios", "positive"]),
    (GOOD + "[motor]\nx = 1\n", ["unknown table [motor]"]),
    ("[vehicle\n", ["not valid TOML"]),
])
def test_bad_files_give_one_line_naming_the_problem(tmp_path, text, words):
    with pytest.raises(VehicleFileError) as info:
        load_vehicle(write(tmp_path, text))
    message = str(info.value)
    assert "\n" not in message
    for word in words:
        assert word in message


def test_missing_file_is_a_clear_error(tmp_path):
    with pytest.raises(VehicleFileError, match="not found"):
        load_vehicle(tmp_path / "nope.toml")
